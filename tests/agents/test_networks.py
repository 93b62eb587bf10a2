"""Shared network pieces: orthogonal initialisation without LAPACK, context inputs normalised by the
feature bounds, the features "concat_varying" picks."""

import jax
import numpy as np
import pytest

import contextrl as crl
from contextrl.agents import ConfigError
from contextrl.agents.networks import context_input, orthogonal, varying_features

pytestmark = pytest.mark.quick


@pytest.mark.parametrize("shape", [(4, 64), (64, 64), (64, 2), (7, 3)])
def test_orthogonal_initialisation(shape):
    q = np.asarray(orthogonal(jax.random.key(0), *shape, 2.0))
    assert q.shape == shape
    gram = q.T @ q if shape[0] >= shape[1] else q @ q.T
    np.testing.assert_allclose(gram, 4.0 * np.eye(len(gram)), atol=1e-5)
    other = np.asarray(orthogonal(jax.random.key(1), *shape, 2.0))
    assert not np.allclose(q, other)


def test_context_vector_is_normalised_by_the_bounds():
    env = crl.make("CartPole")
    space = env.context_space
    inputs = context_input("concat_all", space, env.default_context())
    vector = np.asarray(inputs.vector(space, env.context(length=0.5, gravity=100.0)))
    assert vector.shape == (len(space.names),)
    length = space.names.index("length")
    gravity = space.names.index("gravity")
    assert vector[length] == pytest.approx((0.5 - 0.05) / (5.0 - 0.05))
    assert vector[gravity] == pytest.approx(1.0)
    assert np.all((vector >= 0) & (vector <= 1))


def test_varying_features_of_sets_and_specs():
    env = crl.make("CartPole")
    space = env.context_space
    batch = crl.sample(
        env, {"length": crl.Uniform(0.25, 0.75), "gravity": crl.Constant(5.0)}, 4, jax.random.key(0)
    )
    assert varying_features(space, batch) == ("length",)
    spec = {"pole_length": crl.Uniform(0.25, 0.75), "gravity": crl.Constant(5.0), "tau": 0.01}
    assert varying_features(space, spec) == ("length",)
    inputs = context_input("concat_varying", space, spec)
    assert inputs.view.features == ("length",)
    with pytest.raises(ConfigError, match="no context feature varies"):
        context_input("concat_varying", space, env.default_context())


def test_agents_and_environments_share_one_context_transform():
    env = crl.make("CartPole")
    context = env.context(length=0.5, gravity=20.0)
    seen_by_env = env.with_obs_context("all", normalize=True).reset(jax.random.key(0), context)[1]
    agent_input = context_input("concat_all", env.context_space, env.default_context())
    np.testing.assert_array_equal(
        seen_by_env.obs[4:], agent_input.vector(env.context_space, context)
    )
