"""How far the single gymnasium environment's scalar host path drifts from the compiled step over
whole episodes.

    python benchmarks/host_path_divergence.py --seeds 30

The four deterministic classic-control tasks step a single environment on Python floats (rounded to
float32 after each step; `contextrl.gymnasium.backends.ScalarPhysics`). Each step agrees with the
compiled one to about 1e-4 (tests/envs/classic_control/test_host_path.py); over an episode the
rounding differences can grow. Per task, at the default context and with three dynamics features
(``DRAWN``) drawn in ±20 % of their defaults, each seed runs three episodes of uniform random actions
through both backends (the compiled one forced), the same seed and actions, and the table gives the
largest relative difference of an observation or reward, |a − b| / (1 + |b|), and how many episode
ends differ.
"""

from __future__ import annotations

import argparse
from unittest import mock

import numpy as np

import contextrl as crl
from contextrl.gymnasium import ContextualGymEnv, backends

TASKS = ("CartPole", "Pendulum", "MountainCar", "MountainCarContinuous")


def episodes(name: str, contexts, compiled: bool, seed: int, count: int) -> list[list[tuple]]:
    """``count`` episodes of random actions (drawn from ``seed``) on one backend."""
    chooser = (lambda env: False) if compiled else backends.steps_on_host
    with mock.patch.object(backends, "steps_on_host", chooser):
        env = ContextualGymEnv(name, contexts=contexts, obs_context_features="all")
    assert (type(env.backend) is backends.JaxBackend) == compiled
    rng, space = np.random.default_rng(seed), env.action_space
    obs, _ = env.reset(seed=seed)
    found = []
    for _ in range(count):
        steps = []
        while True:
            if hasattr(space, "n"):
                action = rng.integers(space.n)
            else:
                action = rng.uniform(space.low, space.high).astype(np.float32)
            obs, reward, terminated, truncated, _ = env.step(action)
            steps.append((obs, reward, terminated, truncated))
            if terminated or truncated:
                obs, _ = env.reset()
                break
        found.append(steps)
    return found


# Three dynamics features per task, each drawn in ±20 % of its default.
DRAWN = {
    "CartPole": ("gravity", "masscart", "length"),
    "Pendulum": ("g", "m", "l"),
    "MountainCar": ("gravity", "max_speed", "force"),
    "MountainCarContinuous": ("gravity", "max_speed", "power"),
}


def drawn_contexts(name: str) -> dict:
    default = crl.make(name).default_context()
    values = {feature: float(getattr(default, feature)) for feature in DRAWN[name]}
    return {feature: crl.Uniform(0.8 * v, 1.2 * v) for feature, v in values.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=30)
    parser.add_argument("--episodes", type=int, default=3)
    args = parser.parse_args()
    print("| task | contexts | steps | largest relative difference | episode ends that differ |")
    print("| --- | --- | --- | --- | --- |")
    for name in TASKS:
        for label, contexts in (
            ("default", None),
            ("±20 % on three features", drawn_contexts(name)),
        ):
            worst, ends, steps = 0.0, 0, 0
            for seed in range(args.seeds):
                host = episodes(name, contexts, False, seed, args.episodes)
                compiled = episodes(name, contexts, True, seed, args.episodes)
                for a, b in zip(host, compiled, strict=True):
                    ends += len(a) != len(b)
                    for (obs_a, r_a, *flags_a), (obs_b, r_b, *flags_b) in zip(a, b, strict=False):
                        steps += 1
                        gap = np.abs(obs_a - obs_b) / (1 + np.abs(obs_b))
                        worst = max(worst, float(gap.max()), abs(r_a - r_b) / (1 + abs(r_b)))
                        ends += flags_a != flags_b
            print(f"| {name} | {label} | {steps:,} | {worst:.2g} | {ends} |", flush=True)


if __name__ == "__main__":
    main()
