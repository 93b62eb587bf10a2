"""gymnax CartPole in the same loop as ours, every copy with its own pole length; prints steps/s.

Runs inside a virtual environment that has gymnax (``bench_envs.py --gymnax`` builds one).
"""

import argparse

import gymnax
import jax
from _scan import random_rollout, steps_per_second

parser = argparse.ArgumentParser()
parser.add_argument("--copies", type=int, default=4096)
parser.add_argument("--steps", type=int, default=1000)
parser.add_argument("--devices", type=int, default=1)
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


sample = env.action_space(default_params).sample
run = random_rollout(reset, step, sample, params, args.steps, devices=args.devices)
print(steps_per_second(run, args.copies, args.steps)[1])
