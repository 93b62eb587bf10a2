"""The shared test matrix: every registered JAX environment passes the public checker, and the checker
catches the failure modes it exists for."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import contextrl as crl
from contextrl.envs.classic_control.cartpole import CartPole
from contextrl.testing import check_env, check_feature_effects

# The Brax family runs the checker at small settings in test_brax_agents.py (MJX compiles slowly on CPU).
JAX_IDS = [i for i in crl.registered() if not crl.spec(i).host and crl.spec(i).family != "brax"]


@pytest.mark.parametrize("env_id", JAX_IDS)
def test_check_env(env_id):
    check_env(crl.make(env_id))


def test_check_env_with_visible_noisy_context():
    env = crl.make("CartPole", obs_context_features="all", obs_context_noise=0.1)
    check_env(env, steps=60)


@dataclasses.dataclass(frozen=True)
class StaleMassCartPole(CartPole):
    """CARL's bug: total mass computed once from the default masses, so ``masscart`` does nothing."""

    def transition(self, key, state, action, context):
        default = self.default_context()
        stale = dataclasses.replace(context, masscart=default.masscart)
        return super().transition(key, state, action, stale)


@dataclasses.dataclass(frozen=True)
class UndeclaredGoalCartPole(CartPole):
    """A start-state feature that secretly also ends episodes: an effect it does not declare."""

    def transition(self, key, state, action, context):
        next_state, reward, terminated = super().transition(key, state, action, context)
        return next_state, reward, terminated | (context.initial_state_upper > 0.15)


@dataclasses.dataclass(frozen=True)
class DivergingCartPole(CartPole):
    """A feature value inside its bounds that breaks the physics: a pole of length 0.05 (the lower
    bound) gives NaN, as MJX's contacts did at friction 0."""

    def transition(self, key, state, action, context):
        next_state, reward, terminated = super().transition(key, state, action, context)
        broken = jnp.where(context.length < 0.06, jnp.nan, 0.0)
        return next_state + broken, reward, terminated


def test_checker_catches_a_feature_value_that_diverges():
    with pytest.raises(AssertionError, match=r"length = 0\.05 \(inside its bounds .*non-finite"):
        check_feature_effects(DivergingCartPole(), jax.random.key(0))


def test_checker_catches_a_feature_that_does_nothing():
    with pytest.raises(AssertionError, match="masscart: declared to affect dynamics"):
        check_feature_effects(StaleMassCartPole(), jax.random.key(0))


def test_checker_catches_an_undeclared_effect():
    with pytest.raises(AssertionError, match="initial_state_upper: changes reward or termination"):
        check_feature_effects(UndeclaredGoalCartPole(), jax.random.key(0))


def test_two_instances_never_share_a_context():
    first, second = crl.make("CartPole"), crl.make("CartPole")
    long_pole = first.context(length=2.0)
    short_pole = second.context(length=0.1)
    key = jax.random.key(0)

    def run(env, ctx, interleave_with=None):
        state, _ = env.reset(key, ctx)
        other_state = interleave_with and interleave_with[0].reset(key, interleave_with[1])[0]
        trajectory = []
        for t in range(20):
            state, ts = env.step(jax.random.fold_in(key, t), state, t % 2, ctx)
            if interleave_with:
                env2, ctx2 = interleave_with
                other_state, _ = env2.step(jax.random.fold_in(key, t), other_state, 1, ctx2)
            trajectory.append(np.asarray(ts.obs))
        return np.stack(trajectory)

    alone = run(first, long_pole)
    interleaved = run(first, long_pole, interleave_with=(second, short_pole))
    np.testing.assert_array_equal(alone, interleaved)
    assert not np.array_equal(alone, run(second, short_pole))


def test_auto_reset_keeps_the_final_observation_and_restarts():
    env = crl.make("CartPole", max_steps=5)
    ctx = env.default_context()
    state, ts = env.reset(jax.random.key(0), ctx)
    for t in range(5):
        previous = state
        state, ts = env.step(jax.random.key(t + 1), state, 0, ctx)
    assert bool(ts.truncated) and not bool(ts.terminated)
    assert int(state.time) == 0
    expected_final = env.transition(None, previous.physics, 0, ctx)[0]
    np.testing.assert_allclose(ts.final_obs, expected_final)
    np.testing.assert_allclose(ts.obs, env.init(jax.random.key(5), ctx))


def test_termination_reward_and_truncation_flags_follow_the_original():
    env = crl.make("CartPole")
    ctx = env.default_context()
    state, _ = env.reset(jax.random.key(0), ctx)
    pushes = 0
    while True:
        state, ts = env.step(jax.random.key(pushes), state, 1, ctx)
        pushes += 1
        if bool(ts.done):
            break
    assert bool(ts.terminated) and not bool(ts.truncated)
    assert float(ts.reward) == 1.0  # gymnasium pays the terminating step too
    x, _, theta, _ = np.asarray(ts.final_obs)
    assert abs(x) > 2.4 or abs(theta) > 12 * 2 * np.pi / 360


def test_longer_pole_falls_slower():
    """Physics sanity of a feature: with the same pushes, a longer pole stays up longer."""
    env = crl.make("CartPole")

    def steps_until_fall(length):
        ctx = env.context(length=length)
        state, _ = env.reset(jax.random.key(0), ctx)
        for t in range(500):
            state, ts = env.step(jax.random.key(t), state, 1, ctx)
            if bool(ts.done):
                return t + 1
        return 500

    assert steps_until_fall(0.1) < steps_until_fall(0.5) < steps_until_fall(2.0)


def test_pendulum_gravity_alias_acts_and_start_is_symmetric():
    env = crl.make("Pendulum")
    assert env.context(gravity=3.0).g == pytest.approx(3.0)
    keys = jax.random.split(jax.random.key(0), 4000)
    starts = jax.vmap(env.init, in_axes=(0, None))(keys, env.default_context())
    angle, speed = np.asarray(starts).T
    assert angle.min() < -3.0 and angle.max() > 3.0  # U(−π, π), not U(0, π) as in CARL
    assert speed.min() < -0.95 and speed.max() > 0.95


def test_mountain_car_goals_are_gymnasiums():
    assert float(crl.make("MountainCar").default_context().goal_position) == pytest.approx(0.5)
    continuous = crl.make("MountainCarContinuous").default_context()
    assert float(continuous.goal_position) == pytest.approx(0.45)


def test_acrobot_second_link_length_sets_the_goal_height():
    env = crl.make("Acrobot")
    # Arm horizontal-ish: first link up at 120°, second straight on: tip height −cos(θ1)·l1 − cos(θ1+θ2)·l2.
    state = jnp.array([2.0, 0.0, 0.0, 0.0])
    short = env.context(LINK_LENGTH_2=0.5)
    long = env.context(link_length_2=2.0)
    _, _, ends_short = env.transition(jax.random.key(0), state, 1, short)
    _, _, ends_long = env.transition(jax.random.key(0), state, 1, long)
    assert not bool(ends_short) and bool(ends_long)


def test_max_torque_scales_the_push():
    env = crl.make("Pendulum")
    state = jnp.array([0.0, 0.0])
    strong = env.transition(None, state, jnp.array([2.0]), env.context(max_torque=4.0))[0]
    nominal = env.transition(None, state, jnp.array([2.0]), env.default_context())[0]
    assert float(strong[1]) == pytest.approx(2 * float(nominal[1]))
