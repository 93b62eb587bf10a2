"""The three largest Brax tasks (the humanoids and Pusher, the slowest MJX programs to compile) match
brax step by step at the default context and every declared feature changes their trajectory; in a
file of their own so that `make test`'s two workers (whole files each) share the Brax compile time
(the programs: tests/helpers/brax_rollouts.py)."""

import importlib.util

import numpy as np
import pytest

# Checked without importing brax: brax imports MuJoCo, which must see MUJOCO_GL=egl (set by the family).
if importlib.util.find_spec("brax") is None:
    pytest.skip("brax is not installed", allow_module_level=True)

from tests.helpers.brax_rollouts import (  # noqa: E402
    LARGE,
    assert_every_feature_acts,
    assert_finite_while_running,
    assert_matches_brax,
    rollouts,
)

# In `make test-slow`: the family's parity and feature checks run on the smaller tasks in
# test_brax.py, through the same programs (tests/helpers/brax_rollouts.py).
pytestmark = pytest.mark.slow


@pytest.mark.parametrize("name", LARGE)
def test_default_context_matches_brax_and_every_feature_acts(name):
    rows, ours, theirs = rollouts(name)
    assert_matches_brax(ours, theirs)
    assert_finite_while_running(ours)
    assert_every_feature_acts(rows, ours)
    np.testing.assert_array_equal(ours["reward"], ours["brax_reward"])
