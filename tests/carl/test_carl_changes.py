"""The CARL face with contexts that change within an episode (``changes=``, contextrl's): the core's
step moves the context, and CARL's observation, ``env.context`` and ``info`` follow it."""

import numpy as np
import pytest

import contextrl as crl
from contextrl.carl.envs import CARLCartPole, CARLLunarLander

CHANGE_AT = 3


def test_the_context_shown_follows_the_change():
    env = CARLCartPole(
        contexts={0: {"length": 0.6}},
        obs_context_features=["gravity", "length"],
        changes=crl.Piecewise({CHANGE_AT: {"gravity": 20.0}}),
    )
    obs, info = env.reset(seed=0)
    assert env.context["gravity"] == pytest.approx(9.8)
    seen = []
    for _ in range(CHANGE_AT + 1):
        obs, _, terminated, truncated, info = env.step(0)
        assert not (terminated or truncated)
        seen.append((float(obs["context"]["gravity"][0]), env.context["gravity"]))
        assert info["context"]["gravity"] == pytest.approx(env.context["gravity"])
        assert obs["context"]["length"] == np.float32(0.6)
    expected = [[9.8, 9.8]] * (CHANGE_AT - 1) + [[20.0, 20.0]] * 2
    np.testing.assert_allclose(seen, expected, rtol=1e-6)
    env.reset()  # the next episode starts from its own context
    assert env.context["gravity"] == pytest.approx(9.8)


def test_a_change_the_environment_cannot_run_is_refused():
    with pytest.raises(crl.ContextError, match="'initial_state_lower' cannot change mid-episode"):
        CARLCartPole(changes=crl.Redraw(5, {"initial_state_lower": -0.1}))
    with pytest.raises(crl.ContextError, match="LunarLander is a host environment"):
        CARLLunarLander(changes=crl.Piecewise({5: {"GRAVITY_Y": -5.0}}))
