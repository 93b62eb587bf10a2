"""The public checker on the paper's target-reaching tasks Fetch and UR5e (Grasp's: test_reaching.py):
every feature acts, none acts undeclared (a file of its own, so the suite's workers share the reaching
tests)."""

import importlib.util

import pytest

# Checked without importing brax: brax imports MuJoCo, which must see MUJOCO_GL=egl (set by the family).
if importlib.util.find_spec("brax") is None:
    pytest.skip("brax is not installed", allow_module_level=True)

from contextrl.envs import brax as family  # noqa: E402
from contextrl.testing import check_env  # noqa: E402

# In `make test-slow`: the checker's 64 probes per feature on the arms' largest programs; the
# contexts reaching each copy's physics are checked in test_reaching.py.
pytestmark = pytest.mark.slow


@pytest.mark.parametrize(("name", "max_steps"), [("Fetch", 20), ("Ur5e", 60)])
def test_public_checker_passes_so_every_feature_acts(name, max_steps):
    """The full checker; each feature is probed in 64 (context pair, key) runs of ``max_steps`` random
    steps. The fewest runs showing a declared effect, measured under the suite's flags: Fetch 36 of 64
    (joint_stiffness: a joint must reach its limit); UR5e 12 of 64 (friction: the arm must fall onto
    the floor and slide)."""
    check_env(getattr(family, name)(max_steps=max_steps), num_contexts=4, steps=9)
