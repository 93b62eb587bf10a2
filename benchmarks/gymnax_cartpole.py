"""gymnax CartPole in the same loops as ours, every copy with its own pole length; prints steps/s.

``--batched``: the batch loop (``vmap`` of gymnax's reset/step, a key split per copy per step), the
one ``bench_envs.py`` compares with contextrl's ``step_copies``.

Runs inside a virtual environment that has gymnax (``bench_envs.py --gymnax`` builds one).
"""

import argparse

import gymnax
import jax
from _scan import batched_rollout, random_rollout, steps_per_second

parser = argparse.ArgumentParser()
parser.add_argument("--copies", type=int, default=4096)
parser.add_argument("--steps", type=int, default=1000)
parser.add_argument("--devices", type=int, default=1)
parser.add_argument("--batched", action="store_true")
args = parser.parse_args()

env, default_params = gymnax.make("CartPole-v1")
lengths = jax.random.uniform(jax.random.key(0), (args.copies,), minval=0.25, maxval=0.75)
params = jax.vmap(lambda length: default_params.replace(length=length))(lengths)


def reset(key, p):
    obs, state = env.reset(key, p)
    return state, obs


def step(key, state, action, p):
    obs, state, *_ = env.step(key, state, action, p)
    return state, obs


def reset_batch(key):
    return jax.vmap(reset)(jax.random.split(key, args.copies), params)


def step_batch(key, state, actions):
    return jax.vmap(step)(jax.random.split(key, args.copies), state, actions, params)


if args.batched:
    run = batched_rollout(reset_batch, step_batch, 2, args.steps)
else:
    sample = env.action_space(default_params).sample
    run = random_rollout(reset, step, sample, params, args.steps, devices=args.devices)
print(steps_per_second(run, args.copies, args.steps)[1])
