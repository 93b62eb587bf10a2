"""Train a context-oblivious (hidden) and a context-aware (concat) PPO agent on CartPole whose pole
length is drawn from U(0.25, 0.75) at every reset, then test both on pole lengths inside and outside
the training range.

    python examples/ppo_hidden_vs_concat.py [--seeds 3] [--steps 200000] [--progress]

Each agent's seeds train together in one compiled, vmapped call; the test is one vmapped evaluation
over every (seed, pole length).
"""

import argparse
import time

import jax
import numpy as np

import contextrl as crl
from contextrl.agents import evaluate, ppo

TRAIN = {"length": crl.Uniform(0.25, 0.75)}
TEST_LENGTHS = [0.1, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=200_000)
    parser.add_argument("--episodes", type=int, default=10, help="test episodes per pole length")
    parser.add_argument("--progress", action="store_true", help="print progress lines")
    args = parser.parse_args()

    env = crl.make("CartPole")
    test_contexts = env.context_space.stack([env.context(length=x) for x in TEST_LENGTHS])
    keys = jax.random.split(jax.random.key(0), args.seeds)
    table = {}
    for mode in ("hidden", "concat_varying"):
        config = ppo.PPOConfig(
            total_timesteps=args.steps,
            num_envs=8,
            learning_rate=2.5e-3,
            variant=mode,
            progress_every=20 if args.progress else 0,
        )
        start = time.perf_counter()
        result = jax.jit(jax.vmap(ppo.make_train(config, env, TRAIN)))(keys)
        policy = ppo.make_policy(config, env, TRAIN)
        returns = jax.jit(
            jax.vmap(
                lambda params, key, policy=policy: evaluate(
                    policy, params, env, test_contexts, args.episodes, key
                )
            )
        )(result.params, jax.random.split(jax.random.key(1), args.seeds))
        returns = np.asarray(jax.block_until_ready(returns))
        print(
            f"{mode}: {args.seeds} seeds × {args.steps:,} steps in {time.perf_counter() - start:.1f} s"
        )
        table[mode] = returns

    print("\ntest return per pole length (mean ± std over seeds; trained on U(0.25, 0.75))")
    print(f"{'length':>8}" + "".join(f"{mode:>22}" for mode in table))
    for i, length in enumerate(TEST_LENGTHS):
        cells = "".join(
            f"{np.mean(r[:, i]):>14.1f} ± {np.std(r[:, i]):5.1f}" for r in table.values()
        )
        print(f"{length:>8.2f}{cells}")


if __name__ == "__main__":
    main()
