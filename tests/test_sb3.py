"""Stable-Baselines3 PPO learns contextrl/CartPole-v0 with resampled, visible pole lengths."""

import importlib.util
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "sb3_ppo_cartpole.py"


def _example():
    spec = importlib.util.spec_from_file_location("sb3_ppo_cartpole", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_sb3_ppo_reaches_400_at_the_default_context():
    example = _example()
    untrained = example.train(timesteps=1, seed=0)
    assert example.evaluate(untrained) < 100  # the task is not solved before learning
    score = example.main(["--timesteps", "60000", "--seed", "0"])  # the example as users run it
    assert score >= 400
