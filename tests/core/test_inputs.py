"""The JAX core refuses what cannot be an action or a context when ``reset`` and ``step`` are traced,
once for every environment; values only known inside a compiled step are reported by ``crl.checked``
under ``checkify``."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.experimental import checkify

import contextrl as crl
from contextrl.context.features import ContextError

pytestmark = pytest.mark.quick


@pytest.fixture(scope="module")
def cartpole():
    env = crl.make("CartPole")
    key = jax.random.key(0)
    state, _ = env.reset(key, env.default_context())
    return env, key, state


@pytest.mark.parametrize(
    ("action", "message"),
    [
        (5, r"an integer in \[0, 2\), got 5$"),
        (-1, r"got -1$"),
        (0.7, r"got 0\.7 \(float\)"),
        ("left", r"got 'left' \(str\)"),
        ("", r"got '' \(str\)"),
        (True, r"got True \(bool\)"),
        (np.array([0, 1]), r"got shape \(2,\)"),
    ],
)
def test_what_cannot_be_a_discrete_action_is_refused(cartpole, action, message):
    env, key, state = cartpole
    with pytest.raises(ValueError, match=f"CartPole: an action is .*{message}"):
        env.step(key, state, action, env.default_context())


def test_traced_actions_are_checked_for_kind_and_shape():
    env = crl.make("CartPole")
    key = jax.random.key(0)
    state, _ = env.reset(key, env.default_context())
    step = jax.jit(env.step)
    with pytest.raises(ValueError, match=r"got shape \(3,\)"):
        step(key, state, jnp.zeros(3, jnp.int32), env.default_context())
    with pytest.raises(ValueError, match=r"an integer in \[0, 2\), got .*float32"):
        step(key, state, jnp.float32(1.0), env.default_context())


@pytest.mark.parametrize(
    ("action", "message"),
    [
        (np.array([np.nan], np.float32), r"finite floats of shape \(1,\), got \[nan\]"),
        (np.array([np.inf], np.float32), r"got \[inf\]"),
        (np.zeros(2), r"got shape \(2,\)"),
        (0.5, r"got shape \(\)"),
    ],
)
def test_what_cannot_be_a_box_action_is_refused(action, message):
    env = crl.make("Pendulum")
    key = jax.random.key(0)
    state, _ = env.reset(key, env.default_context())
    with pytest.raises(ValueError, match=f"Pendulum: an action is .*{message}"):
        env.step(key, state, action, env.default_context())


def test_a_dict_context_is_converted_and_anything_else_refused(cartpole):
    env, key, _ = cartpole
    by_dict = env.reset(key, {"length": 0.9})[1].obs
    by_context = env.reset(key, env.context(length=0.9))[1].obs
    np.testing.assert_array_equal(by_dict, by_context)
    with pytest.raises(ContextError, match=r"length: value 99 is outside its bounds"):
        env.reset(key, {"length": 99.0})
    expected = r"CartPole expects a CartPoleContext .* or a dict of its feature values, got"
    with pytest.raises(ContextError, match=f"{expected} NoneType"):
        env.reset(key, None)
    with pytest.raises(ContextError, match=f"{expected} PendulumContext"):
        env.reset(key, crl.make("Pendulum").default_context())


def test_a_tuple_where_a_distribution_is_expected_is_named():
    env = crl.make("CartPole")
    with pytest.raises(ContextError, match=r"length: \(0\.2, 0\.7\) is not a distribution"):
        crl.sample(env, {"length": (0.2, 0.7)}, 8, jax.random.key(0))


def test_checked_env_reports_run_time_values_under_checkify(cartpole):
    env, key, state = cartpole
    context = env.default_context()
    # Unchecked, a compiled step does not look at the value (documented).
    jax.jit(env.step)(key, state, 5, context)
    step = checkify.checkify(
        jax.jit(jax.vmap(crl.checked(env).step, in_axes=(None, None, 0, None)))
    )
    error, _ = step(key, state, jnp.array([0, 1, 1]), context)
    error.throw()  # every action valid: nothing to report
    error, _ = step(key, state, jnp.array([0, 7, 1]), context)
    with pytest.raises(checkify.JaxRuntimeError, match=r"CartPole: an action is .* got 7"):
        error.throw()
    pendulum = crl.checked(crl.make("Pendulum"))
    p_state, _ = pendulum.reset(key, pendulum.default_context())
    p_step = checkify.checkify(jax.jit(pendulum.step))
    error, _ = p_step(key, p_state, jnp.array([jnp.nan]), pendulum.default_context())
    with pytest.raises(checkify.JaxRuntimeError, match=r"Pendulum: .* got \[nan\]"):
        error.throw()
    # The checks need checkify: a plain jit of the checked env says so instead of ignoring them.
    with pytest.raises(ValueError, match="checkify"):
        jax.jit(crl.checked(env).step)(key, state, 1, context)
