"""SAC on a host environment (DmcWalker, dm_control) through contextrl's shared host collector against
Stable-Baselines3's SAC with the same networks (256×256 actor and twin critics), the same batch size,
warm-up and update ratio (one critic and one actor update per environment step), in one run.

    python benchmarks/bench_sac_host.py                  # 4,000 steps each (1,000 warm-up)
    python benchmarks/bench_sac_host.py --steps 20000

Prints training steps per second of both (compile / model building included; the warm-up runs without
updates in both) and their ratio.
"""

from __future__ import annotations

import argparse
import time

import gymnasium
import jax

import contextrl as crl  # noqa: F401  (registers contextrl/<Id>-v0)
from contextrl.agents import sac


def contextrl_sac(steps: int, warmup: int, env_id: str) -> float:
    config = sac.SACConfig(
        total_timesteps=steps,
        learning_starts=warmup,
        num_envs=1,
        batch_size=256,
        policy_frequency=1,
        hidden_sizes=(256, 256),
        log_every=1000,
    )
    env = crl.make(env_id)
    contexts = env.context_space.stack([env.default_context()])
    start = time.perf_counter()
    sac.train_gymnasium(config, env_id, contexts, jax.random.key(0), seed=0)
    return time.perf_counter() - start


def sb3_sac(steps: int, warmup: int, env_id: str) -> float:
    import torch
    from stable_baselines3 import SAC

    torch.set_num_threads(1)
    start = time.perf_counter()
    env = gymnasium.make(f"contextrl/{env_id}-v0")
    model = SAC(
        "MlpPolicy",
        env,
        batch_size=256,
        learning_starts=warmup,
        train_freq=1,
        gradient_steps=1,
        policy_kwargs={"net_arch": [256, 256]},
        seed=0,
        device="cpu",
    )
    model.learn(total_timesteps=steps)
    env.close()
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--warmup", type=int, default=1000)
    parser.add_argument("--env", default="DmcWalker")
    args = parser.parse_args()
    ours = contextrl_sac(args.steps, args.warmup, args.env)
    theirs = sb3_sac(args.steps, args.warmup, args.env)
    rows = [
        ("contextrl SAC (host collector)", ours),
        ("Stable-Baselines3 SAC", theirs),
    ]
    print(f"{args.env}, {args.steps:,} steps ({args.warmup:,} warm-up), 256×256, batch 256")
    print(f"{'agent':<32} {'seconds':>9} {'steps/s':>9}")
    for name, seconds in rows:
        print(f"{name:<32} {seconds:>9.1f} {args.steps / seconds:>9.1f}")
    print(f"ratio (contextrl / SB3 steps/s): {theirs / ours:.2f}×")


if __name__ == "__main__":
    main()
