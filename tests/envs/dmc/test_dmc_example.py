"""The DmcWalker visibility example runs end to end and shows the viscosity only when asked."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from tests.helpers import learning

pytest.importorskip("stable_baselines3")
pytest.importorskip("dm_control")


def test_visibility_example_trains_both_variants_and_tests_on_held_out_viscosities():
    example = learning.load_example("dmc_walker_visibility")
    hidden = example.make_env("hidden", {"viscosity": 2.0}, 10).reset(seed=0)[0]
    thin = example.make_env("visible", {"viscosity": 1.0}, 10).reset(seed=0)[0]
    thick = example.make_env("visible", {"viscosity": 2.0}, 10).reset(seed=0)[0]
    assert hidden.shape == (24,) and thin.shape == thick.shape == (25,)
    np.testing.assert_array_equal(
        thin[:24], hidden
    )  # same seed, same start: only the context differs
    assert thick[-1] > thin[-1]

    viscosities = example.test_viscosities(3)
    assert np.all((viscosities >= 1.0) & (viscosities <= 2.5))
    results = example.main(
        ["--timesteps", "200", "--seeds", "1", "--test-contexts", "2", "--max-steps", "20"]
    )
    assert set(results) == {"hidden", "visible"}
    for returns in results.values():
        assert returns.shape == (1, 2) and np.all(np.isfinite(returns)) and np.all(returns >= 0)
