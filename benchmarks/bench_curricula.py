"""What a curriculum's bookkeeping costs the compiled PPO loop, at 64 and 1,024 copies.

    python benchmarks/bench_curricula.py [--copies 64 1024] [--updates 8] [--repeats 3]

PPO trains CartPole for ``--updates`` updates of 128 steps per copy, once over a fixed pool of 64
contexts (each rollout draws from it uniformly: the plain loop) and once under each curriculum over
the same pool (SPaCE, PLR) or over the pole length's whole range (ADR), every loop compiled once and
then timed; the calls alternate so a shared machine's load falls on all alike, and the best of
``--repeats`` is kept. The overhead is a curriculum's time over the plain loop's, minus one.
"""

import argparse
import os
import time

import jax

import contextrl as crl
from contextrl.agents import ppo
from contextrl.context import Uniform
from contextrl.context.curricula import ADR, PLR, SPaCE

POOL_SIZE = 64
LENGTHS = (0.05, 5.0)


def load() -> str:
    try:
        return f"{os.getloadavg()[0]:.1f}"
    except OSError:
        return "unknown"


def loops(copies: int, updates: int) -> dict:
    """name → jitted ``train(key)`` for the plain pool and each curriculum."""
    env = crl.make("CartPole")
    pool = crl.sample(env, {"length": Uniform(*LENGTHS)}, POOL_SIZE, jax.random.key(1))
    config = ppo.PPOConfig(
        total_timesteps=updates * copies * 128,
        num_envs=copies,
        num_steps=128,
        hidden_sizes=(64, 64),
    )
    taught = {
        "pool": pool,
        "space": SPaCE(pool, initial=8, step=8),
        "plr": PLR(pool),
        "adr": ADR(env.context_space, {"length": LENGTHS}, widen_above=150.0, narrow_below=50.0),
    }
    made = {}
    for name, contexts in taught.items():
        train = ppo.make_train(config, env, contexts)
        made[name] = jax.jit(lambda key, train=train: train(key).metrics["episode_return"])
    return made


def measure(copies: int, updates: int, repeats: int) -> dict[str, float]:
    made = loops(copies, updates)
    for name, function in made.items():
        start = time.perf_counter()
        jax.block_until_ready(function(jax.random.key(0)))
        print(
            f"  {copies} copies, {name}: compiled and ran once in {time.perf_counter() - start:.1f} s"
        )
    best = {name: float("inf") for name in made}
    for repeat in range(repeats):
        for name, function in made.items():
            start = time.perf_counter()
            jax.block_until_ready(function(jax.random.key(repeat + 1)))
            best[name] = min(best[name], time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, nargs="+", default=[64, 1024])
    parser.add_argument("--updates", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(
        f"jax {jax.__version__} on {jax.devices()[0].platform}, load average {load()} at the start"
    )
    rows = []
    for copies in args.copies:
        best = measure(copies, args.updates, args.repeats)
        steps = args.updates * copies * 128
        for name, seconds in best.items():
            overhead = seconds / best["pool"] - 1.0
            rows.append((copies, name, seconds, steps / seconds, overhead))
    print(f"load average {load()} at the end")
    print("| copies | training contexts | seconds | steps/s | overhead vs the pool |")
    print("| --- | --- | --- | --- | --- |")
    for copies, name, seconds, rate, overhead in rows:
        shown = "—" if name == "pool" else f"{100 * overhead:+.1f} %"
        print(f"| {copies:,} | {name} | {seconds:.2f} | {rate:,.0f} | {shown} |")


if __name__ == "__main__":
    main()
