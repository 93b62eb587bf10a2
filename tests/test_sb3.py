"""Stable-Baselines3 PPO learns contextrl/CartPole-v0 with resampled, visible pole lengths."""

import pytest

pytest.importorskip("stable_baselines3")

import learning  # noqa: E402  (tests/learning.py: the runs shared with the margin script)


def test_sb3_ppo_learns_cartpole_with_resampled_pole_lengths():
    """examples/sb3_ppo_cartpole.py as users run it, 60k steps, seed 0; the greedy policy's mean return
    at the default context (the untrained policy scores below 100).

    MEASURED_SB3
    """
    example = learning._example("sb3_ppo_cartpole")
    assert example.evaluate(example.train(timesteps=1, seed=0)) < 100  # not solved before learning
    assert learning.sb3_cartpole([0])["return"][0] >= SB3_THRESHOLD
