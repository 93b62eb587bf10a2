"""The gymnax 1.0 face: gymnax's state fields, params with the time limit, opt-in transition gradients,
registration; the transitions are the core's (tools/run_gymnax_suite.py runs gymnax's own tests)."""

import dataclasses
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import contextrl as crl
import contextrl.gymnax.v1 as gymnax


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class GymnaxCartPoleState:
    """gymnax's own ``cartpole.EnvState``: the same fields, another class."""

    x: float
    x_dot: float
    theta: float
    theta_dot: float
    time: int


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class PendulumLike:
    theta: float
    time: int


def test_state_has_gymnax_fields_and_views_the_core_state():
    env, params = gymnax.make("CartPole-v1")
    core = crl.make("CartPole")
    key = jax.random.key(0)
    obs, state = env.reset(key, params)
    core_state, _ = core.reset(key, core.default_context())
    assert isinstance(state, gymnax.CartPoleState) and int(state.time) == 0
    np.testing.assert_array_equal(state.core.physics, core_state.physics)
    np.testing.assert_array_equal([state.x, state.x_dot, state.theta, state.theta_dot], obs)
    obs, state, *_ = env.step(key, state, 1, params)
    core_state, timestep = core.step(key, core_state, 1, core.default_context())
    np.testing.assert_array_equal(obs, timestep.obs)
    assert int(state.time) == 1 and float(state.x_dot) == float(core_state.physics[1])
    # gymnax's own state classes step too: any pytree with the fields
    fallen = GymnaxCartPoleState(0.0, 0.0, 0.3, 0.0, 0)
    assert bool(env.step(key, fallen, 0, params)[3])  # past the 12° threshold: terminated
    assert bool(env.step(key, state.replace(theta=jnp.float32(0.3)), 0, params)[3])
    with pytest.raises(TypeError, match=r"CartPole-v1: a state has the fields \['x'"):
        env.step(key, PendulumLike(0.0, 0), 0, params)


def test_pendulum_state_keeps_the_last_action_clipped():
    env, params = gymnax.make("Pendulum-v1")
    _, state = env.reset(jax.random.key(0), params)
    assert float(state.last_u) == 0.0
    _, state, *_ = env.step(jax.random.key(1), state, jnp.array([3.0]), params)
    assert float(state.last_u) == 2.0


def test_params_carry_the_time_limit_and_read_features_by_name():
    env, params = gymnax.make("CartPole-v1", max_steps=50)
    assert int(params.max_steps_in_episode) == 50 and float(params.length) == pytest.approx(0.5)
    assert float(params.total_mass) == pytest.approx(1.1)  # derived from the context, never stale
    assert float(params.theta_threshold_radians) == pytest.approx(12 * 2 * np.pi / 360)
    short = params.replace(max_steps_in_episode=3, length=0.8)
    assert float(short.length) == pytest.approx(0.8) and int(short.max_steps_in_episode) == 3
    obs, state = env.reset(jax.random.key(0), short)
    flags = []
    for t in range(4):
        obs, state, _, terminated, truncated, info = env.step(
            jax.random.key(t), state, t % 2, short
        )
        flags.append((bool(terminated), bool(truncated), int(state.time)))
    assert flags == [(False, False, 1), (False, False, 2), (False, True, 0), (False, False, 1)]
    with pytest.raises(crl.ContextError, match="follow from the context"):
        params.replace(total_mass=2.0)
    with pytest.raises(crl.ContextError, match="length"):
        params.replace(length=50.0)
    with pytest.raises(ValueError, match="max_steps_in_episode must be an integer"):
        params.replace(max_steps_in_episode=0)
    with pytest.raises(ValueError, match="max_steps_in_episode must be an integer"):
        params.replace(max_steps_in_episode=2.5)
    with pytest.raises(AttributeError, match="unknown context feature 'colour'"):
        params.colour  # noqa: B018


def test_a_batch_of_bare_contexts_steps_under_makes_time_limit():
    env, params = gymnax.make("CartPole-v1", max_steps=2)
    batch = crl.sample(params.context, {"length": crl.Uniform(0.25, 2.0)}, 3, jax.random.key(0))
    keys = jax.random.split(jax.random.key(1), 3)
    _, state = jax.vmap(env.reset)(keys, batch)
    step = jax.vmap(env.step)
    _, state, *_ = step(keys, state, jnp.ones(3, jnp.int32), batch)
    _, state, _, _, truncated, _ = step(keys, state, jnp.ones(3, jnp.int32), batch)
    assert bool(jnp.all(truncated)) and bool(jnp.all(state.time == 0))


def test_transition_gradients_are_opt_in_and_only_for_continuous_actions():
    env, params = gymnax.make("Pendulum-v1")
    state = gymnax.PendulumState(jnp.float32(0.5), jnp.float32(0.2), jnp.float32(0.0), 0)

    def theta_dot_of(environment, context):
        def theta_dot(u):
            return environment.step(jax.random.key(0), state, u, context)[1].theta_dot

        return jax.grad(lambda u: theta_dot(u)[()])

    u = jnp.array([0.4])
    assert float(theta_dot_of(env, params)(u)[0]) == 0.0  # gymnax's default: stopped
    differentiable = env.with_transition_gradients()
    assert differentiable.transition_gradients_enabled and not env.transition_gradients_enabled
    heavy = params.replace(m=2.0, max_torque=4.0)  # torque = u · max_torque / 2
    expected = 3.0 / (2.0 * 1.0**2) * 0.05 * 2.0
    assert float(theta_dot_of(differentiable, heavy)(u)[0]) == pytest.approx(expected, rel=1e-5)
    cartpole, _ = gymnax.make("CartPole-v1")
    with pytest.raises(ValueError, match="CartPole-v1 does not support transition gradients"):
        cartpole.with_transition_gradients()


def test_state_space_names_the_fields_with_and_without_gymnax(monkeypatch):
    env, params = gymnax.make("MountainCar-v0")
    _, state = env.reset(jax.random.key(0), params)
    assert set(env.state_space(params).spaces) == {"position", "velocity", "time"}
    assert bool(env.state_space(params).contains(state))
    monkeypatch.setitem(sys.modules, "gymnax", None)
    space = env.state_space(params.replace(max_steps_in_episode=7))
    assert isinstance(space, gymnax.Dict) and space.spaces["time"].n == 7
    assert space.contains(state)


class Constant:
    """A user's own gymnax-style environment: reward ``reward`` every step."""

    def __init__(self, reward=1.0):
        self.default_params = reward

    def reset(self, key, params):
        return jnp.zeros(1), jnp.int32(0)

    def step(self, key, state, action, params):
        return jnp.zeros(1), state + 1, jnp.float32(params), False, False, {}


def test_register_adds_a_users_environment_to_make(monkeypatch):
    registration = gymnax.registration
    monkeypatch.setattr(registration, "_registry", dict(registration._registry))
    monkeypatch.setattr(registration, "registered_envs", list(registration.registered_envs))
    gymnax.register("Constant-v0", Constant)
    env, params = gymnax.make("Constant-v0", reward=2.0)
    assert params == 2.0 and "Constant-v0" in registration.registered_envs
    with pytest.raises(ValueError, match="already registered"):
        gymnax.register("CartPole-v1", Constant)
    with pytest.raises(ValueError, match="NotThere-v0 is not in registered gymnax environments"):
        gymnax.make("NotThere-v0")
    env, _ = gymnax.make("CartPole")  # contextrl's ids reach the registered environment
    assert env.name == "CartPole-v1"
