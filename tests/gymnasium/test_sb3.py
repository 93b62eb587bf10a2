"""Stable-Baselines3 PPO learns contextrl/CartPole-v0 with resampled, visible pole lengths."""

import pytest

pytest.importorskip("stable_baselines3")

from tests.helpers import learning


# SB3 runs unchanged on the faces in make test: tests/carl/test_carl.py (DQN on a CARL id) and
# tests/envs/dmc/test_dmc_example.py (PPO on dm_control); its learning is checked here, in the slow tier.
@pytest.mark.slow
def test_sb3_ppo_learns_cartpole_with_resampled_pole_lengths():
    """examples/sb3_ppo_cartpole.py as users run it, 60k steps, seed 0; the greedy policy's mean return
    at the default context (the untrained policy scores below 100).

    Measured (tests/helpers/margins.py; the run does not go through XLA, so the second numerics
    is torch's kernels without SIMD, ATEN_CPU_CAPABILITY=default): default, seeds 0–7: min 299,
    seven of eight 500; without SIMD, seeds 100–103: min 279, three of four 500. A seed reaching
    400 is therefore luck about once in six; >= 200 holds with a margin (worst measured 279).
    """
    example = learning.load_example("sb3_ppo_cartpole")
    assert example.evaluate(example.train(timesteps=1, seed=0)) < 100  # not solved before learning
    assert learning.sb3_cartpole([0])["return"][0] >= 200
