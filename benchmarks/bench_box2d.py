"""Box2D family: one env against gymnasium and CARL, the cost of a context switch, 64 copies vs envpool.

    python benchmarks/bench_box2d.py [--steps 20000] [--switches 300] [--skip-peers]

Prints three tables:
1. steps/s of one environment with a non-default context under seeded random actions (finished episodes
   reset), through ``gymnasium.make``: gymnasium's original at its default (timed in alternating blocks
   with ours, so the load of a shared machine falls on both alike) and CARL 1.1.1's ``CARLLunarLander``
   / ``CARLBipedalWalker`` with the same context (in ``.venv-carl``);
2. the cost of a context switch at reset: a reset alternating between two contexts against one that
   keeps its context, on the host environment and through the gymnasium adapter (a two-context set);
3. copy-steps/s of 64 copies through ``gymnasium.make_vec`` (one process) against envpool's C++
   ``LunarLander-v3`` / ``BipedalWalker-v3`` with 64 envs on one thread (in ``.venv-envpool``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import gymnasium
import numpy as np

import contextrl
from contextrl.envs.box2d import BipedalWalker, LunarLander

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _peers import CARL_BOX2D, ENVPOOL, ENVPOOL_STEPS, run_peer  # noqa: E402

CONTEXTS = {  # a non-default context per environment, the same for CARL
    "LunarLander": {"GRAVITY_Y": -5.0, "MAIN_ENGINE_POWER": 20.0, "LEG_SPRING_TORQUE": 60.0},
    "BipedalWalker": {"FRICTION": 1.5, "MOTORS_TORQUE": 100.0, "GRAVITY_Y": -8.0},
}
ORIGINALS = {"LunarLander": "LunarLander-v3", "BipedalWalker": "BipedalWalker-v3"}
SWITCH = {  # two contexts alternated at every reset
    "LunarLander": ({}, {"GRAVITY_Y": -2.0, "SCALE": 40.0, "VIEWPORT_W": 800}),
    "BipedalWalker": ({}, {"FRICTION": 5.0, "TERRAIN_STEP": 0.6, "LEG_H": 1.3}),
}

CARL_SCRIPT = """
import json, sys, time, warnings
warnings.filterwarnings("ignore")
import numpy as np
from carl.envs import CARLLunarLander, CARLBipedalWalker
name, context, steps = sys.argv[1], json.loads(sys.argv[2]), int(sys.argv[3])
env = {"LunarLander": CARLLunarLander, "BipedalWalker": CARLBipedalWalker}[name](contexts={0: context})
env.reset(seed=0)
rng = np.random.default_rng(0)
if name == "LunarLander":
    actions = [int(a) for a in rng.integers(0, 4, steps)]
else:
    actions = list(rng.uniform(-1, 1, (steps, 4)).astype(np.float32))
def run(part):
    for action in part:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
run(actions[:500])
start = time.perf_counter()
run(actions)
print(json.dumps({"steps_per_s": steps / (time.perf_counter() - start)}))
"""


def random_actions(space, count: int, seed: int = 0) -> list:
    rng = np.random.default_rng(seed)
    if isinstance(space, gymnasium.spaces.Discrete):
        return [int(a) for a in rng.integers(0, space.n, count)]
    return list(rng.uniform(space.low, space.high, (count, *space.shape)).astype(np.float32))


def run_block(env, actions) -> float:
    """Seconds to step ``actions`` (resetting finished episodes)."""
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return time.perf_counter() - start


def single(name: str, steps: int, block: int = 500) -> tuple[float, float]:
    """Steps/s of gymnasium's original and of ours with a non-default context, alternating blocks."""
    original = gymnasium.make(ORIGINALS[name])
    ours = gymnasium.make(f"contextrl/{name}-v0", contexts=CONTEXTS[name])
    actions = random_actions(original.action_space, steps)
    times = [0.0, 0.0]
    for env in (original, ours):
        env.reset(seed=0)
        run_block(env, actions[:block])  # warm-up
    for begin in range(0, steps, block):
        for side, env in enumerate((original, ours)):
            times[side] += run_block(env, actions[begin : begin + block])
    original.close()
    ours.close()
    return steps / times[0], steps / times[1]


def switch_cost(cls, name: str, count: int) -> dict[str, float]:
    """Microseconds per reset keeping the context and per reset switching it, measured interleaved,
    on the env and through gymnasium (a one-context set against a two-context set in round robin).
    Each figure is the 25th percentile of its resets: on a loaded machine the scheduler preempts
    many resets for tens of milliseconds, which says nothing about the reset itself."""
    env = cls()
    first, second = (env.context(**values) for values in SWITCH[name])
    rng = np.random.default_rng(0)
    same, switch = [], []
    env.reset_physics(first, rng)
    for _ in range(count):
        for context, times in ((first, same), (second, switch), (first, switch)):
            start = time.perf_counter()
            env.reset_physics(context, rng)
            times.append(time.perf_counter() - start)
    out = {"env same": quartile(same), "env switch": quartile(switch)}
    keep = gymnasium.make(f"contextrl/{name}-v0", contexts=[SWITCH[name][0]])
    alternate = gymnasium.make(f"contextrl/{name}-v0", contexts=list(SWITCH[name]))
    times = {keep: [], alternate: []}
    for gym_env in times:
        gym_env.reset(seed=0)
    for _ in range(count):
        for gym_env, spent in times.items():
            start = time.perf_counter()
            gym_env.reset()
            spent.append(time.perf_counter() - start)
    out["gym same"] = quartile(times[keep])
    out["gym switch"] = quartile(times[alternate])
    keep.close()
    alternate.close()
    return out


def quartile(seconds: list[float]) -> float:
    """The 25th percentile in microseconds."""
    return float(np.percentile(seconds, 25)) * 1e6


def vector(name: str, copies: int, calls: int) -> float:
    """Copy-steps/s of ``gymnasium.make_vec`` with one context per copy (one process)."""
    space = contextrl.make(name).context_space
    feature = "GRAVITY_Y"
    low, high = (-12.0, -2.0) if name == "LunarLander" else (-12.0, -6.0)
    contexts = [{feature: float(g)} for g in np.linspace(low, high, copies)]
    space.make(**contexts[0])
    envs = gymnasium.make_vec(
        f"contextrl/{name}-v0", num_envs=copies, vectorization="sync", contexts=contexts
    )
    envs.reset(seed=0)
    single_space = envs.single_action_space
    actions = np.stack(
        [np.stack(random_actions(single_space, copies, seed)) for seed in range(calls)]
    )
    for action in actions[:20]:
        envs.step(action)
    start = time.perf_counter()
    for action in actions:
        envs.step(action)
    rate = calls * copies / (time.perf_counter() - start)
    envs.close()
    return rate


def table(rows: list[list[str]]) -> str:
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="single-env steps per row")
    parser.add_argument("--switches", type=int, default=300, help="resets per switch row")
    parser.add_argument("--vector-calls", type=int, default=200, help="vector steps of 64 copies")
    parser.add_argument("--skip-peers", action="store_true", help="do not measure CARL or envpool")
    args = parser.parse_args(argv)
    names = ("LunarLander", "BipedalWalker")

    rows = [
        ["env (non-default context)", "gymnasium", "CARL 1.1.1", "contextrl", "× gym", "× CARL"]
    ]
    for name in names:
        original, ours = single(name, args.steps)
        carl = None
        if not args.skip_peers:
            script_args = (name, json.dumps(CONTEXTS[name]), args.steps)
            carl = run_peer(CARL_BOX2D, CARL_SCRIPT, *script_args)["steps_per_s"]
        rows.append(
            [
                name,
                f"{original:.3g}",
                f"{carl:.3g}" if carl else "-",
                f"{ours:.3g}",
                f"{ours / original:.2f}",
                f"{ours / carl:.2f}" if carl else "-",
            ]
        )
    print("1. one environment, steps/s\n" + table(rows) + "\n")

    rows = [
        ["env", "env same µs", "env switch µs", "switch cost µs", "gym same µs", "gym switch µs"]
    ]
    for cls, name in ((LunarLander, "LunarLander"), (BipedalWalker, "BipedalWalker")):
        cost = switch_cost(cls, name, args.switches)
        rows.append(
            [
                name,
                f"{cost['env same']:.0f}",
                f"{cost['env switch']:.0f}",
                f"{cost['env switch'] - cost['env same']:.0f}",
                f"{cost['gym same']:.0f}",
                f"{cost['gym switch']:.0f}",
            ]
        )
    print("2. reset with and without a context switch\n" + table(rows) + "\n")

    copies = 64
    rows = [["env", f"contextrl make_vec ({copies}, sync)", "envpool (1 thread)", "× envpool"]]
    for name in names:
        ours = vector(name, copies, args.vector_calls)
        peer = None
        if not args.skip_peers:
            peer = run_peer(ENVPOOL, ENVPOOL_STEPS, ORIGINALS[name], copies, 1, args.vector_calls)
            peer = peer["steps_per_s"]
        ratio = f"{ours / peer:.2f}" if peer else "-"
        rows.append([name, f"{ours:.3g}", f"{peer:.3g}" if peer else "-", ratio])
    print(f"3. {copies} copies, copy-steps/s\n" + table(rows))


if __name__ == "__main__":
    main()
