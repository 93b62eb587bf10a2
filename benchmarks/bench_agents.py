"""Wall time and agent steps per second of whole training runs, many seeds in one compiled call.

    python benchmarks/bench_agents.py [--seeds 10] [--only ppo c51 sac] [--scale 0.1]

The runs: PPO on CartPole (10 seeds × 500,000 steps, compile included in the wall time),
C51 on CartPole (10 seeds × 100,000 steps; ``c51-paper``: the paper's C51 setting, one environment copy,
256×256, a gradient step and a soft target update every step) and SAC on Pendulum (10 seeds × 50,000
steps). Compilation is
timed apart from the run; steps/s counts environment steps of all seeds together. After training, each
seed's deterministic policy is evaluated (10 episodes, default context) so a fast but broken run shows.
``--scale`` multiplies every step budget (for a quick look); ``--config`` prints the configs used.
"""

import argparse
import time

import jax
import numpy as np

import contextrl as crl
from contextrl.agents import dqn, evaluate, ppo, sac

RUNS = {
    "ppo": ("PPO", "CartPole", ppo, lambda steps: ppo.PPOConfig(total_timesteps=steps), 500_000),
    "c51": (
        "C51",
        "CartPole",
        dqn,
        lambda steps: dqn.DQNConfig(
            total_timesteps=steps, distributional=True, v_min=0.0, v_max=110.0
        ),
        100_000,
    ),
    "c51-paper": (
        "C51 (paper)",
        "CartPole",
        dqn,
        lambda steps: dqn.paper_config("CartPole", total_timesteps=steps),
        100_000,
    ),
    "sac": ("SAC", "Pendulum", sac, lambda steps: sac.SACConfig(total_timesteps=steps), 50_000),
}


def run(name: str, seeds: int, scale: float, show_config: bool) -> dict:
    label, env_id, module, make_config, steps = RUNS[name]
    env = crl.make(env_id)
    config = make_config(max(int(steps * scale), 1))
    if show_config:
        print(f"{label}: {config}")
    context = env.default_context()
    train = jax.jit(jax.vmap(module.make_train(config, env, context)))
    keys = jax.random.split(jax.random.key(0), seeds)

    start = time.perf_counter()
    compiled = train.lower(keys).compile()
    compile_seconds = time.perf_counter() - start
    start = time.perf_counter()
    result = jax.block_until_ready(compiled(keys))
    run_seconds = time.perf_counter() - start

    done = int(np.asarray(result.metrics["step"])[0, -1])
    policy = module.make_policy(config, env, context)
    returns = jax.jit(
        jax.vmap(lambda params, key: evaluate(policy, params, env, context, 10, key))
    )(result.params, jax.random.split(jax.random.key(1), seeds))
    returns = np.asarray(returns).ravel()
    return {
        "run": f"{label} {env_id}",
        "seeds × steps": f"{seeds} × {done:,}",
        "compile s": compile_seconds,
        "run s": run_seconds,
        "total s": compile_seconds + run_seconds,
        "steps/s": seeds * done / run_seconds,
        "s per agent per 100k steps": run_seconds / seeds * 100_000 / done,
        "eval return (min / mean)": f"{returns.min():.1f} / {returns.mean():.1f}",
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument(
        "--only", nargs="+", choices=sorted(RUNS), default=["ppo", "c51", "c51-paper", "sac"]
    )
    parser.add_argument("--scale", type=float, default=1.0, help="multiply every step budget")
    parser.add_argument("--config", action="store_true", help="print the configs used")
    args = parser.parse_args()

    print(f"device: {jax.devices()[0].device_kind}, {jax.device_count()} device(s)")
    rows = []
    for name in args.only:
        rows.append(run(name, args.seeds, args.scale, args.config))
        print(f"done: {rows[-1]}", flush=True)
    header = list(rows[0])
    widths = [
        max(len(h), *(len(f"{r[h]:,.1f}" if isinstance(r[h], float) else r[h]) for r in rows))
        for h in header
    ]
    print("  ".join(h.rjust(w) for h, w in zip(header, widths, strict=True)))
    for r in rows:
        cells = [f"{r[h]:,.1f}" if isinstance(r[h], float) else r[h] for h in header]
        print("  ".join(c.rjust(w) for c, w in zip(cells, widths, strict=True)))
    for r in rows:
        if r["run"].startswith("PPO"):
            print(f"PPO total / 60 s target: {r['total s'] / 60:.2f}")


if __name__ == "__main__":
    main()
