"""Steps per second through the gymnasium API: CARL, gymnasium, envpool, our single and vector envs.

    python benchmarks/bench_gymnasium.py [--steps 20000] [--skip-carl] [--skip-envpool]

CARL (``carl-bench==1.1.1``) and envpool are measured in their own virtual environments,
``.venv-carl`` and ``.venv-envpool``, created here on first use (they pin versions that must not enter
the project's environment). Every row runs random actions from a seeded generator and resets finished
episodes, the way a training loop would. The single-env table's ratios are against CARL's
``CARLCartPole`` and gymnasium's ``CartPole-v1``; the vector table counts steps of single copies
(``num_envs`` per call) of CartPole, ours with a pole length per copy, against envpool's
``CartPole-v1`` on one thread. Each side is timed ``--rounds`` times, alternating, and the best kept, so
a busy machine penalises both alike.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _peers import CARL, ENVPOOL, ENVPOOL_STEPS, run_peer  # noqa: E402

VECTOR_SIZES = (8, 64, 1024)

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


def bench_envpool(num_envs: int, steps: int) -> float:
    return run_peer(ENVPOOL, ENVPOOL_STEPS, "CartPole-v1", num_envs, 1, max(50, steps // num_envs))[
        "steps_per_s"
    ]


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
    """Copy-steps/s of the compiled vector env (auto-reset inside the call), a pole length per copy."""
    import gymnasium
    import jax

    import contextrl as crl

    lengths = crl.sample(
        crl.make("CartPole"), {"length": crl.Uniform(0.25, 0.75)}, num_envs, jax.random.key(0)
    )
    envs = gymnasium.make_vec("contextrl/CartPole-v0", num_envs=num_envs, contexts=lengths)
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


def print_table(title: str, rows: list[tuple[str, float]], peers: dict[str, float]) -> None:
    """Rows of steps/s with one ratio column per peer."""
    width = max(len(name) for name, _ in rows)
    header = f"{'what'.ljust(width)}  {'steps/s':>10}" + "".join(f"  × {p:>8}" for p in peers)
    print(f"\n{title}\n{header}\n{'-' * len(header)}")
    for name, rate in rows:
        ratios = "".join(f"  {rate / peer:10.2f}" for peer in peers.values())
        print(f"{name.ljust(width)}  {rate:10.3e}{ratios}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="single-env steps per row")
    parser.add_argument("--rounds", type=int, default=3, help="alternating timings, best kept")
    parser.add_argument("--skip-carl", action="store_true", help="do not measure CARL")
    parser.add_argument("--skip-envpool", action="store_true", help="do not measure envpool")
    args = parser.parse_args(argv)

    import gymnasium

    import contextrl  # noqa: F401  (registers contextrl/<Id>-v0)

    def best(measure) -> float:
        return max(measure() for _ in range(args.rounds))

    single = {
        "gymnasium CartPole-v1": lambda: bench_single(gymnasium.make("CartPole-v1"), args.steps),
        "contextrl gymnasium.make('contextrl/CartPole-v0')": lambda: bench_single(
            gymnasium.make("contextrl/CartPole-v0"), args.steps
        ),
        "contextrl, 8 contexts round robin, visible": lambda: bench_single(
            gymnasium.make(
                "contextrl/CartPole-v0",
                contexts=[{"length": 0.1 * (i + 1)} for i in range(8)],
                obs_context_features="varying",
            ),
            args.steps,
        ),
    }
    if not args.skip_carl:
        single = {"CARL 1.1.1 CARLCartPole": lambda: bench_carl(args.steps), **single}
    rates = {name: 0.0 for name in single}
    for _ in range(args.rounds):  # alternate, so load hits every row alike
        for name, measure in single.items():
            rates[name] = max(rates[name], measure())
    peers = {"gymnasium": rates["gymnasium CartPole-v1"]}
    if not args.skip_carl:
        peers = {"CARL": rates["CARL 1.1.1 CARLCartPole"], **peers}
    print_table("Single env, CartPole, one step per call", list(rates.items()), peers)

    vector_rows: list[tuple[str, float]] = []
    for num_envs in VECTOR_SIZES:
        ours = theirs = 0.0
        for _ in range(args.rounds):
            ours = max(ours, bench_vector(num_envs, args.steps * 10))
            if not args.skip_envpool:
                theirs = max(theirs, bench_envpool(num_envs, args.steps * 10))
        vector_rows.append((f"contextrl vector env, {num_envs} copies", ours))
        if theirs:
            vector_rows.append(
                (
                    f"envpool {ENVPOOL[1][0].split('==')[1]} CartPole-v1, {num_envs} copies, 1 thread",
                    theirs,
                )
            )
    if args.skip_envpool:
        print_table("Vector env, CartPole", vector_rows, {})
    else:
        print("\nVector env, CartPole (ratio: contextrl / envpool at the same number of copies)")
        width = max(len(name) for name, _ in vector_rows)
        for (name, ours), (peer, theirs) in zip(vector_rows[::2], vector_rows[1::2], strict=True):
            print(f"{name.ljust(width)}  {ours:10.3e}")
            print(
                f"{peer.ljust(width)}  {theirs:10.3e}   contextrl / envpool = {ours / theirs:.2f}"
            )

    core = [
        (f"core jit(vmap(env.step)), {n} copies, no gymnasium", bench_core(n, args.steps * 10))
        for n in (64, 1024)
    ]
    print_table("Floor: the compiled step alone", core, {})


if __name__ == "__main__":
    main()
