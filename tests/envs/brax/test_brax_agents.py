"""Brax through the public pieces: the checker (with MuJoCo's medium, so viscosity acts), the gymnasium
face with a time limit and rendering, and SAC learning InvertedPendulum (PPO's learning tests on the
family: test_reaching_learning.py)."""

import importlib.util

import gymnasium
import gymnasium.utils.env_checker
import numpy as np
import pytest

# Checked without importing brax: brax imports MuJoCo, which must see MUJOCO_GL=egl (set by the family).
if importlib.util.find_spec("brax") is None:
    pytest.skip("brax is not installed", allow_module_level=True)

from contextrl.envs import brax as family  # noqa: E402
from contextrl.testing import check_env  # noqa: E402
from tests.helpers import learning


def test_public_checker_passes_with_the_medium_model():
    """The full checker (no recompilation, same key same trajectory, truncation, every declared effect)
    on InvertedPendulum with MuJoCo's medium on (``fluid=True``), so ``viscosity`` must act too."""
    env = family.InvertedPendulum(max_steps=4, fluid=True)
    assert "viscosity" in env.context_space.names
    check_env(env, num_contexts=4, steps=9)


def test_time_limit_truncates_through_the_gymnasium_face():
    env = gymnasium.make(
        "contextrl/BraxInvertedPendulum-v0",
        contexts=[{"mass_pole": 2.0}, {"mass_pole": 8.0}],
        max_steps=3,
        render_mode="rgb_array",
    )
    gymnasium.utils.env_checker.check_env(env.unwrapped, skip_render_check=True)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs) and info["context"]["mass_pole"] == 2.0
    ends = []
    for _ in range(3):
        obs, reward, terminated, truncated, info = env.step(np.zeros(1, np.float32))
        ends.append((terminated, truncated))
    assert ends == [(False, False), (False, False), (False, True)]
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.std() > 0
    env.close()


@pytest.mark.slow  # SAC's compiled loop learns in tests/agents/test_sac.py
def test_sac_learns_inverted_pendulum():
    """SAC, 3,000 steps (2 copies, 500 random warm-up transitions, then an update per step), seeds
    0–3 in one vmapped call: the mean episode return of the first and the last of six log rows.

    Measured (tests/helpers/margins.py): default numerics, seeds 0–15: first 4.1–6.0, last
    57.6–104.8; fast math, seeds 100–107: first 4.1–6.5, last 65.3–90.3. Every seed's last row
    above 30 and above 3 × its first holds with a margin (worst measured: 57.6, and 8.9 ×).
    """
    statistics = learning.brax_sac_pendulum(range(4))
    first, last = statistics["first_rows"], statistics["last_rows"]
    assert np.all(first < 15), first
    assert np.all(last > 30) and np.all(last > 3 * first), (first, last)
