"""At the default context every classic-control environment is its gymnasium original.

Each step starts gymnasium from exactly our state, takes the same action and compares the next state,
observation, reward and termination; start-state distributions are compared with a two-sample KS test.
"""

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

import contextrl as crl

GYM_IDS = {
    "CartPole": "CartPole-v1",
    "Pendulum": "Pendulum-v1",
    "MountainCar": "MountainCar-v0",
    "MountainCarContinuous": "MountainCarContinuous-v0",
    "Acrobot": "Acrobot-v1",
}


def gym_action(env, action):
    action = np.asarray(action)
    return action.astype(np.float32) if action.ndim else int(action)


def set_gym_state(gym_env, state):
    gym_env.state = np.asarray(state, dtype=np.float64)


@pytest.mark.parametrize("env_id", sorted(GYM_IDS))
def test_steps_match_gymnasium(env_id):
    env = crl.make(env_id)
    ctx = env.default_context()
    gym_env = gymnasium.make(GYM_IDS[env_id]).unwrapped
    transition = jax.jit(env.transition)
    observe = jax.jit(env.observe)
    init = jax.jit(env.init)
    key = jax.random.key(0)
    compared = terminations = 0
    for episode in range(20):
        key, start_key = jax.random.split(key)
        state = init(start_key, ctx)
        gym_env.reset(seed=episode)  # clears gymnasium's record of the previous episode's end
        for _ in range(150):
            key, action_key, step_key = jax.random.split(key, 3)
            action = env.action_space.sample(action_key)
            set_gym_state(gym_env, state)
            gym_obs, gym_reward, gym_terminated, gym_truncated, _ = gym_env.step(
                gym_action(env, action)
            )
            state, reward, terminated = transition(step_key, state, action, ctx)
            np.testing.assert_allclose(np.asarray(state), gym_env.state, rtol=2e-5, atol=2e-6)
            np.testing.assert_allclose(observe(state, ctx), gym_obs, rtol=2e-5, atol=2e-6)
            assert float(reward) == pytest.approx(float(gym_reward), rel=1e-5, abs=1e-6)
            assert bool(terminated) == gym_terminated
            assert not gym_truncated
            compared += 1
            if gym_terminated:
                terminations += 1
                break
    assert compared >= 300
    if env_id == "CartPole":
        assert terminations == 20  # random pushes topple the pole: termination was compared too


@pytest.mark.parametrize("env_id", sorted(GYM_IDS))
def test_time_limit_matches_gymnasium(env_id):
    assert crl.make(env_id).max_steps == gymnasium.make(GYM_IDS[env_id]).spec.max_episode_steps


@pytest.mark.parametrize("env_id", sorted(GYM_IDS))
def test_start_states_match_gymnasium(env_id):
    env = crl.make(env_id)
    ctx = env.default_context()
    keys = jax.random.split(jax.random.key(1), 2000)
    ours = np.asarray(jax.vmap(env.reset, in_axes=(0, None))(keys, ctx)[1].obs)
    gym_env = gymnasium.make(GYM_IDS[env_id])
    theirs = np.stack([gym_env.reset(seed=seed)[0] for seed in range(2000)])
    assert ours.shape == theirs.shape
    for column in range(ours.shape[1]):
        if np.ptp(theirs[:, column]) == 0:  # a constant start variable (a car at rest)
            np.testing.assert_allclose(ours[:, column], theirs[0, column], atol=1e-7)
        else:
            assert stats.ks_2samp(ours[:, column], theirs[:, column]).pvalue > 1e-3


def test_acrobot_wrap_matches_gymnasium_loop():
    from gymnasium.envs.classic_control.acrobot import wrap as gym_wrap

    from contextrl.envs.classic_control.acrobot import wrap

    values = np.array([-20.0, -3.2, -3.14, 0.0, 3.14, 3.2, 7.0, 20.0, 100.0], dtype=np.float32)
    expected = [gym_wrap(float(v), -np.pi, np.pi) for v in values]
    np.testing.assert_allclose(wrap(jnp.asarray(values), -jnp.pi, jnp.pi), expected, atol=1e-5)
