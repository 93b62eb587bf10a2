"""One step of every environment at its default context, the cheapest proof that each family still
builds, resets and steps: in `make test-quick`. Brax's tasks, whose MJX programs take minutes to compile
on a CPU, build their default system in brax/test_default_system.py instead."""

import jax
import numpy as np
import pytest

import contextrl as crl
from contextrl.core.spaces import Discrete

pytestmark = pytest.mark.quick

IDS = crl.registered()


def zero_action(space):
    """The first discrete action, or the middle of a box: a valid action for every environment."""
    if isinstance(space, Discrete) or hasattr(space, "n"):
        return np.int32(0)
    return ((np.asarray(space.low) + np.asarray(space.high)) / 2).astype(np.float32)


@pytest.mark.parametrize("env_id", [i for i in IDS if crl.spec(i).host])
def test_host_environment_steps_once_at_its_default_context(env_id):
    env = crl.make(env_id)
    obs = env.reset_physics(env.default_context(), np.random.default_rng(0))
    assert env.base_observation_space.contains(np.asarray(obs, env.base_observation_space.dtype))
    obs, reward, terminated = env.step_physics(zero_action(env.action_space))
    assert np.isfinite(obs).all() and np.isfinite(reward) and not terminated
    env.close()


@pytest.mark.parametrize(
    "env_id", [i for i in IDS if not crl.spec(i).host and crl.spec(i).family != "brax"]
)
def test_jax_environment_steps_once_at_its_default_context(env_id):
    env = crl.make(env_id)
    context = env.default_context()
    state, first = jax.jit(env.reset)(jax.random.key(0), context)
    state, step = jax.jit(env.step)(
        jax.random.key(1), state, zero_action(env.action_space), context
    )
    assert first.obs.shape == step.obs.shape == env.observation_space.shape
    assert np.isfinite(np.asarray(step.obs)).all() and np.isfinite(float(step.reward))
    assert int(state.time) == 1 and not bool(step.done)
