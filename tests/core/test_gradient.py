"""The return's gradient with respect to the context equals central finite differences, and every input
it cannot differentiate is refused in one line before anything runs.

The finite differences step each feature by ±0.3 % of its value (at least 3e-5) in float32, under the
same fixed key as the gradient. Measured for the cases below (key 0), with XLA's default flags and with
the suite's: the largest relative difference between gradient and finite difference is 8.7e-4 on
CartPole (masspole) and 3.2e-4 on Pendulum (max_torque); at ±1 % and ±0.1 % steps it stays within
7.4e-3 (the float32 rounding of the return grows as the step shrinks, the curvature as it grows). The
tolerance, 1e-2 of the gradient (or of 1e-2 where the gradient is smaller), clears those at the test's
±0.3 % by more than ten times. Over keys 0 to 7 the same steps differ by up to 3.5e-2 on CartPole
(key 2, tau): there the ±0.3 % step moves the pole's fall across a step boundary (the return passes
8.0), a kink of the return, which is why the key is fixed. Without the terminating step's fraction
CartPole's return is an integer and its gradient zero, which the last assertion of the first test
refuses.
"""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import contextrl as crl
from contextrl.context import ContextBase
from contextrl.core.env import Env
from contextrl.core.spaces import Box

pytestmark = pytest.mark.quick

KEY = jax.random.key(0)
RELATIVE_STEP = 3e-3
TOLERANCE = 1e-2
PENDULUM_GAINS = jnp.array([0.0, -3.0, -1.0])


def push_right(obs):
    return 1


def hold_up(obs):
    """A smooth policy that holds the pendulum up under weak gravity (it never reaches the clip)."""
    return 2.0 * jnp.tanh(PENDULUM_GAINS @ obs)[None]


CASES = {
    "CartPole": (push_right, 50, {}),
    "Pendulum": (hold_up, 50, {"g": 2.0, "initial_angle_max": 1.0}),
}


def central_difference(return_of, values, name):
    value = float(values[name])
    step = RELATIVE_STEP * max(abs(value), 1e-2)
    up, down = jnp.float32(value + step), jnp.float32(value - step)
    higher = float(return_of({**values, name: up}))
    lower = float(return_of({**values, name: down}))
    return (higher - lower) / (float(up) - float(down))


@pytest.mark.parametrize("env_id", sorted(CASES))
def test_gradient_equals_central_differences(env_id):
    policy, horizon, values = CASES[env_id]
    env = crl.make(env_id)
    context = env.context(**values)
    gradient = crl.context_gradient(env, policy, context, key=KEY, horizon=horizon)
    floats = [n for n, f in env.context_space.features.items() if f.kind == "float"]
    assert list(gradient) == floats
    return_of, at_context = crl.return_of_context(env, policy, context, key=KEY, horizon=horizon)
    return_of = jax.jit(return_of)
    for name, derivative in gradient.items():
        difference = central_difference(return_of, at_context, name)
        assert abs(difference - derivative) <= TOLERANCE * max(abs(derivative), 1e-2), (
            name,
            derivative,
            difference,
        )
    assert sum(abs(d) > 0.1 for d in gradient.values()) >= 5  # the check is not of zeros


def test_cartpole_counts_the_terminating_step_by_its_fraction():
    """The return lies in (k − 1, k] where the episode terminates in step k, and is not an integer:
    the terminating step counts by the part of it spent inside the limits."""
    env = crl.make("CartPole")
    context = env.default_context()
    return_of, values = crl.return_of_context(env, push_right, context, key=KEY, horizon=50)
    smooth = float(return_of(values))
    state, ts = env.reset(jax.random.split(KEY)[0], context)
    steps = 0
    while not bool(ts.terminated):
        state, ts = env.advance(KEY, state, 1, context)
        steps += 1
    assert steps - 1 < smooth < steps
    only_gravity = crl.context_gradient(
        env, push_right, context, key=KEY, horizon=50, features=["gravity", "pole_length"]
    )
    assert list(only_gravity) == ["gravity", "length"]


@crl.context_type
class SwitchContext(ContextBase):
    gain: float = crl.feature(1.0, 0.0, 2.0, doc="scale of the push")
    mode: int = crl.feature("soft", 0, 0, kind="categorical", choices=("soft", "hard"))


@dataclasses.dataclass(frozen=True)
class Switch(Env):
    """A one-variable system with a categorical feature, declared differentiable."""

    context_type = SwitchContext
    default_max_steps = 10
    differentiable = True

    @property
    def action_space(self):
        return Box(np.array([-1.0]), np.array([1.0]))

    @property
    def base_observation_space(self):
        return Box(np.array([-10.0]), np.array([10.0]))

    def init(self, key, context):
        return jnp.zeros(1)

    def transition(self, key, state, action, context):
        return state + context.gain * action, -jnp.sum(state**2), jnp.zeros((), bool)

    def observe(self, state, context):
        return state


def refusal(env, policy=push_right, context=None, **options):
    options = {"key": KEY, "horizon": 10, **options}
    context = env.default_context() if context is None else context
    with pytest.raises((ValueError, TypeError)) as caught:
        crl.context_gradient(env, policy, context, **options)
    message = str(caught.value)
    assert "\n" not in message
    return message


def test_host_environments_are_refused():
    message = refusal(crl.make("LunarLander"))
    assert "LunarLander is a host environment" in message
    assert "differentiable environments: CartPole, Pendulum" in message


def test_jax_environments_not_declared_differentiable_are_refused():
    message = refusal(crl.make("Acrobot"), policy=lambda obs: 1)
    assert "Acrobot's dynamics are not declared differentiable" in message
    assert "CartPole, Pendulum" in message


def test_a_categorical_feature_is_refused():
    message = refusal(Switch(), policy=lambda obs: obs, features=["gain", "mode"])
    assert "Switch's feature mode is categorical, which has no gradient" in message
    assert "float features: ['gain']" in message
    assert list(
        crl.context_gradient(
            Switch(), lambda obs: obs, Switch().default_context(), key=KEY, horizon=3
        )
    ) == ["gain"]


def test_bad_inputs_are_refused_before_anything_runs():
    env = crl.make("CartPole")
    assert "length: value nan is not finite" in refusal(env, context={"length": math.nan})
    assert "gravity: value inf is not finite" in refusal(env, context={"gravity": math.inf})
    batch = crl.sample(env, {"length": crl.Uniform(0.4, 0.6)}, n=3, key=KEY)
    assert "one context of CartPole, got a batch of shape (3,)" in refusal(env, context=batch)
    assert "key must be one JAX key" in refusal(env, key=0)
    assert "key must be one JAX key" in refusal(env, key=jax.random.split(KEY, 2))
    assert "horizon must be in [1, 500]" in refusal(env, horizon=501)
    assert "horizon must be an integer" in refusal(env, horizon=2.5)
    assert "unknown context feature 'mass'" in refusal(env, features=["mass"])
    assert "feature length given twice" in refusal(env, features=["length", "pole_length"])
    assert "policy must be a function" in refusal(env, policy=1)
    assert "an action is an integer in [0, 2)" in refusal(env, policy=lambda obs: obs)
