"""Steps per second through the gymnasium API: CARL, gymnasium, our single env, our vector env.

    python benchmarks/bench_gymnasium.py [--steps 20000] [--skip-carl]

CARL (``carl-bench==1.1.1``) is measured in its own virtual environment, ``.venv-carl``, created here on
first use (it pins old versions that must not enter the project's environment). Every row runs random
actions from a seeded generator and resets finished episodes, the way a training loop would. Vector rows
count steps of single copies (``num_envs`` per call). Ratios are against CARL's ``CARLCartPole``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _peers import CARL, run_peer  # noqa: E402

CARL_SCRIPT = """
import json, sys, time, warnings
warnings.filterwarnings("ignore")
import numpy as np
from carl.envs import CARLCartPole
steps = int(sys.argv[1])
env = CARLCartPole()
env.reset(seed=0)
actions = np.random.default_rng(0).integers(0, 2, steps)
for action in actions[:1000]:
    if any(env.step(int(action))[2:4]):
        env.reset()
start = time.perf_counter()
for action in actions:
    _, _, terminated, truncated, _ = env.step(int(action))
    if terminated or truncated:
        env.reset()
print(json.dumps({"steps_per_s": steps / (time.perf_counter() - start)}))
"""


def bench_carl(steps: int) -> float:
    return run_peer(CARL, CARL_SCRIPT, steps)["steps_per_s"]


def bench_single(env, steps: int) -> float:
    """Steps/s of a gymnasium env under random actions, resetting finished episodes."""
    env.reset(seed=0)
    actions = np.random.default_rng(0).integers(0, 2, steps)
    for action in actions[:1000]:  # warm-up: compilation, caches
        if any(env.step(int(action))[2:4]):
            env.reset()
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(int(action))
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def bench_vector(num_envs: int, steps: int) -> float:
    """Copy-steps/s of the compiled vector env (auto-reset inside the call)."""
    from contextrl.gymnasium import ContextualVectorEnv

    envs = ContextualVectorEnv("CartPole", num_envs=num_envs)
    envs.reset(seed=0)
    calls = max(50, steps // num_envs)
    actions = np.random.default_rng(0).integers(0, 2, (calls, num_envs))
    for action in actions[:20]:
        envs.step(action)
    start = time.perf_counter()
    for action in actions:
        envs.step(action)
    return calls * num_envs / (time.perf_counter() - start)


def bench_core(num_envs: int, steps: int) -> float:
    """Copy-steps/s of the core's own compiled step (``jit(vmap(env.step))``), without gymnasium.

    The floor under the vector env: the same compiled physics with no host round trip for actions,
    observations or infos.
    """
    import jax

    import contextrl as crl

    env = crl.make("CartPole")
    contexts = crl.sample(env, {"length": crl.Uniform(0.25, 0.75)}, num_envs, jax.random.key(0))
    keys = jax.random.split(jax.random.key(1), num_envs)
    state, _ = jax.vmap(env.reset)(keys, contexts)
    step = jax.jit(jax.vmap(env.step))
    actions = jax.numpy.zeros(num_envs, jax.numpy.int32)
    calls = max(50, steps // num_envs)
    for _ in range(20):
        state, timestep = step(keys, state, actions, contexts)
    timestep.obs.block_until_ready()
    start = time.perf_counter()
    for _ in range(calls):
        state, timestep = step(keys, state, actions, contexts)
    timestep.obs.block_until_ready()
    return calls * num_envs / (time.perf_counter() - start)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="single-env steps per row")
    parser.add_argument("--skip-carl", action="store_true", help="do not measure CARL")
    args = parser.parse_args(argv)

    import gymnasium

    import contextrl  # noqa: F401  (registers contextrl/<Id>-v0)
    from contextrl.gymnasium import ContextualGymEnv

    rows: list[tuple[str, float]] = []
    carl = None if args.skip_carl else bench_carl(args.steps)
    if carl is not None:
        rows.append(("CARL 1.1.1 CARLCartPole (one env)", carl))
    rows.append(
        ("gymnasium CartPole-v1 (one env)", bench_single(gymnasium.make("CartPole-v1"), args.steps))
    )
    rows.append(
        (
            "contextrl gymnasium.make('contextrl/CartPole-v0')",
            bench_single(gymnasium.make("contextrl/CartPole-v0"), args.steps),
        )
    )
    rows.append(
        (
            "contextrl ContextualGymEnv (unwrapped)",
            bench_single(ContextualGymEnv("CartPole"), args.steps),
        )
    )
    rows.append(
        (
            "contextrl single, 8 contexts round robin, visible",
            bench_single(
                ContextualGymEnv(
                    "CartPole",
                    contexts=[{"length": 0.1 * (i + 1)} for i in range(8)],
                    obs_context_features="varying",
                ),
                args.steps,
            ),
        )
    )
    for num_envs in (1, 8, 64, 1024):
        rows.append(
            (f"contextrl vector env, {num_envs} copies", bench_vector(num_envs, args.steps * 10))
        )

    for num_envs in (64, 1024):
        rows.append(
            (
                f"core jit(vmap(env.step)), {num_envs} copies, no gymnasium",
                bench_core(num_envs, args.steps * 10),
            )
        )

    width = max(len(name) for name, _ in rows)
    header = f"{'what'.ljust(width)}  {'steps/s':>12}" + ("  × CARL" if carl else "")
    print(header)
    print("-" * len(header))
    for name, rate in rows:
        ratio = f"  {rate / carl:7.2f}" if carl else ""
        print(f"{name.ljust(width)}  {rate:12.3e}{ratio}")


if __name__ == "__main__":
    main()
