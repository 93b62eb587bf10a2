"""Where contextrl's PPO on Brax InvertedDoublePendulum spends the time PureJaxRL's does not.

    python benchmarks/ppo_brax_gap.py [--steps 100000] [--seeds 5] [--rounds 2]

The learning table's PPO Brax row (``learning.py --only ppo_brax``) at a smaller budget, in one
process, timed in alternating calls (best of ``--rounds``) after compiling each variant:

1. The environment alone, 64 copies of random actions on the positional pipeline: brax's own
   environment (``brax.envs.create``: its time limit and auto-reset, what PureJaxRL's
   BraxGymnaxWrapper builds) vmapped, against ``ContextualEnv.step_copies`` restarting every copy at
   every step and keeping the restart where an episode ended (its path below
   ``contextual.GATHER_FROM`` copies), and against its path that restarts only the ended copies.
2. The whole training run at the row's settings, the seeds in one vmapped call: as the row runs it;
   without the value of the final observation at a time-limit cut (``ppo._time_limit_reward`` bound
   to the plain reward); and with ``step_copies`` restarting only the ended copies.

The differences between the variants are the costs of those parts.
"""

import argparse
import json
import os
import pathlib
import sys

import jax

from contextrl.xla_flags import xla_cpu_workaround

xla_cpu_workaround()

import contextrl as crl  # noqa: E402
from contextrl.agents import ppo  # noqa: E402
from contextrl.core import contextual  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from _contextual import contextual_rollout  # noqa: E402
from bench_brax import best_rates, brax_rollout  # noqa: E402
from learning import BRAX_PPO_SETTINGS  # noqa: E402

COPIES = BRAX_PPO_SETTINGS["num_envs"]


def best_seconds(sides: dict, rounds: int) -> dict:
    """Each compiled (run, argument)'s best seconds over ``rounds`` calls made in turn."""
    rates = best_rates(list(sides.values()), 1, rounds)  # one call per "step": calls per second
    return {name: 1 / rate for name, rate in zip(sides, rates, strict=True)}


def compiled(run, argument):
    """``run`` traced and compiled now, with the module-level switches in force now."""
    return run.lower(jax.random.key(0), argument).compile()


def training(env, steps: int, seeds: int):
    """Compiled (key, unused) → a checksum of the trained params: the row's PPO, ``seeds`` runs
    vmapped."""
    config = ppo.PPOConfig(
        total_timesteps=steps, hidden_sizes=(256, 256), activation="tanh", **BRAX_PPO_SETTINGS
    )
    train = jax.vmap(ppo.make_train(config, env, env.default_context()))

    def run(key, _):
        params = train(jax.random.split(key, seeds)).params
        return sum(leaf.sum() for leaf in jax.tree_util.tree_leaves(params))

    run = jax.jit(run)
    return compiled(run, 0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100_000, help="environment steps per seed")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    env = crl.make("BraxInvertedDoublePendulum", backend="positional")
    contexts = env.default_context()
    env_steps = args.steps * args.seeds // COPIES

    rollouts = {
        "brax's environment (auto-reset)": (compiled(brax_rollout(env, COPIES, env_steps), 0), 0),
        "contextrl, every copy restarted": (
            compiled(contextual_rollout(env, COPIES, env_steps), contexts),
            contexts,
        ),
    }
    trainings = {"contextrl's PPO, as in the row": training(env, args.steps, args.seeds)}
    plain_reward = ppo._time_limit_reward
    ppo._time_limit_reward = lambda value, params, step, context_vector, gamma: step.reward
    trainings["without the time-limit bootstrap"] = training(env, args.steps, args.seeds)
    ppo._time_limit_reward = plain_reward
    gather_from = contextual.GATHER_FROM
    contextual.GATHER_FROM = 1
    rollouts["contextrl, only ended copies restarted"] = (
        compiled(contextual_rollout(env, COPIES, env_steps), contexts),
        contexts,
    )
    trainings["only ended copies restarted"] = training(env, args.steps, args.seeds)
    contextual.GATHER_FROM = gather_from

    total = env_steps * COPIES
    load = os.getloadavg()[0]
    rollout_s = best_seconds(rollouts, args.rounds)
    training_s = best_seconds({name: (run, 0) for name, run in trainings.items()}, args.rounds)
    results = {"steps": total, "load": load, "rollout_s": rollout_s, "training_s": training_s}
    print(f"{total:,} environment steps ({args.seeds} seeds × {args.steps:,}), {COPIES} copies")
    for name, seconds in rollout_s.items():
        print(f"  environment only, {name}: {seconds:.1f} s ({total / seconds:,.0f} steps/s)")
    for name, seconds in training_s.items():
        print(f"  training, {name}: {seconds:.1f} s")
    results["load_end"] = os.getloadavg()[0]
    print(json.dumps(results))


if __name__ == "__main__":
    main()
