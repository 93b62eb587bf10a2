"""The host (Python float) path of the classic-control envs agrees with their JAX transition, and the
single gymnasium env that steps on it follows the JAX backend's trajectories."""

from __future__ import annotations

import math
import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import contextrl as crl
from contextrl.core import scalar
from contextrl.core.spaces import Discrete
from contextrl.gymnasium import ContextualGymEnv
from contextrl.gymnasium.backends import JaxBackend, ScalarBackend

ENVS = ("CartPole", "Pendulum", "MountainCar", "MountainCarContinuous", "Acrobot")
BATCH = 64


def random_contexts(env, rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` context vectors uniform inside the declared bounds (float32, as the JAX path holds them)."""
    space = env.context_space
    low, high = np.asarray(space.lower, np.float64), np.asarray(space.upper, np.float64)
    vectors = (low + rng.uniform(size=(n, len(space.names))) * (high - low)).astype(np.float32)
    if "torque_noise_max" in space.names:
        vectors[:, space.names.index("torque_noise_max")] = 0.0  # noise has its own test
    return vectors


def random_states(name: str, contexts: np.ndarray, names, rng: np.random.Generator) -> np.ndarray:
    """States spread over where each env's state lives (float32)."""
    n = len(contexts)
    if name == "CartPole":
        high = np.array([2.4, 3.0, 0.2, 3.0])
        states = rng.uniform(-high, high, (n, 4))
    elif name == "Pendulum":
        states = rng.uniform([-2 * math.pi, -8.0], [2 * math.pi, 8.0], (n, 2))
    elif name.startswith("MountainCar"):
        lower = contexts[:, names.index("min_position")]
        upper = contexts[:, names.index("max_position")]
        position = lower + rng.uniform(size=n) * (upper - lower)
        states = np.stack([position, rng.uniform(-0.07, 0.07, n)], axis=1)
    else:
        states = rng.uniform([-math.pi, -math.pi, -4.0, -9.0], [math.pi, math.pi, 4.0, 9.0], (n, 4))
    return states.astype(np.float32)


def random_actions(env, rng: np.random.Generator, n: int) -> np.ndarray:
    if isinstance(env.action_space, Discrete):
        return rng.integers(0, env.action_space.n, n).astype(np.int32)
    return rng.uniform(-2.5, 2.5, (n, 1)).astype(np.float32)  # beyond the bounds: clipping acts


def host_context(space, vector: np.ndarray) -> types.SimpleNamespace:
    return types.SimpleNamespace(**dict(zip(space.names, vector.tolist(), strict=True)))


@pytest.mark.parametrize("name", ENVS)
def test_host_transition_matches_jax(name):
    env = crl.make(name)
    space = env.context_space
    rng = np.random.default_rng(7)
    contexts = random_contexts(env, rng, BATCH)
    states = random_states(name, contexts, space.names, rng)
    actions = random_actions(env, rng, BATCH)

    def jax_step(state, action, vector):
        context = space.from_array(vector)
        next_state, reward, terminated = env.transition(jax.random.key(0), state, action, context)
        return next_state, reward, terminated, env.observe(next_state, context)

    next_states, rewards, terminated, observations = jax.jit(jax.vmap(jax_step))(
        jnp.asarray(states), jnp.asarray(actions), jnp.asarray(contexts)
    )
    for i in range(BATCH):
        context = host_context(space, contexts[i])
        action = int(actions[i]) if actions.ndim == 1 else actions[i].tolist()
        state, reward, done = env.host_transition(states[i].tolist(), action, context, None)
        where = f"{name} context {contexts[i]} state {states[i]} action {actions[i]}"
        np.testing.assert_allclose(state, next_states[i], rtol=1e-4, atol=1e-4, err_msg=where)
        np.testing.assert_allclose(reward, rewards[i], rtol=1e-4, atol=1e-4, err_msg=where)
        assert bool(done) == bool(terminated[i]), where
        observed = env.host_observe(state, context)
        np.testing.assert_allclose(observed, observations[i], rtol=1e-4, atol=1e-4, err_msg=where)
    # The sample reaches what it is meant to test: the episode-ending branch where there is one.
    if name in ("CartPole", "Acrobot", "MountainCar"):
        assert np.asarray(terminated).any() and not np.asarray(terminated).all()


def test_acrobot_host_noise_comes_from_the_episode_generator():
    env = crl.make("Acrobot")
    context = host_context(
        env.context_space,
        np.asarray(env.context_space.to_array(env.context(torque_noise_max=0.5)), np.float32),
    )
    state = [0.1, -0.2, 0.3, 0.0]
    first = env.host_transition(state, 1, context, np.random.default_rng(3))[0]
    again = env.host_transition(state, 1, context, np.random.default_rng(3))[0]
    other = env.host_transition(state, 1, context, np.random.default_rng(4))[0]
    assert first == again and first != other
    noise = float(np.random.default_rng(3).uniform(-0.5, 0.5))
    from contextrl.envs.classic_control.acrobot import dynamics

    expected = dynamics(scalar, scalar.stack(state), 1 - 1.0 + noise, context)[0]
    assert first == expected


def gym_pair(name: str, **kwargs) -> tuple[ContextualGymEnv, ContextualGymEnv]:
    """The same single env twice: stepping on the host (the default) and through compiled JAX."""
    host = ContextualGymEnv(name, **kwargs)
    compiled = ContextualGymEnv(name, **kwargs)
    compiled.backend = JaxBackend(compiled.contextrl_env, compiled.schedule)
    assert isinstance(host.backend, ScalarBackend)
    return host, compiled


@pytest.mark.parametrize("name", ENVS)
def test_single_env_follows_the_jax_trajectories(name):
    env = crl.make(name)
    rng = np.random.default_rng(11)
    # Within a factor of two of the defaults: near the bounds' extremes (Pendulum with a 0.5 s step on
    # a 1 cm pole) float32 and float64 trajectories part ways, as any two roundings of such dynamics do;
    # single steps over the whole bounds are compared above.
    space = env.context_space
    default = np.asarray(space.to_array(space.default()), np.float64)
    vectors = default * rng.uniform(0.5, 1.5, (3, len(space.names)))
    vectors = np.clip(vectors, space.lower, space.upper).astype(np.float32)
    contexts = [space.from_array(vector) for vector in vectors]
    host, compiled = gym_pair(name, contexts=contexts, obs_context_features="varying", max_steps=40)
    obs_host, info_host = host.reset(seed=5)
    obs_jax, info_jax = compiled.reset(seed=5)
    ends = 0
    for _ in range(150):
        # float64 on the host, float32 in JAX: rounding differences compound along an episode.
        np.testing.assert_allclose(obs_host, obs_jax, rtol=1e-3, atol=1e-3)
        assert obs_host.dtype == np.float32 and host.observation_space.contains(obs_host)
        assert info_host == info_jax
        action = random_action(host, rng)
        obs_host, reward_host, term_host, trunc_host, info_host = host.step(action)
        obs_jax, reward_jax, term_jax, trunc_jax, info_jax = compiled.step(action)
        assert isinstance(reward_host, float)
        assert reward_host == pytest.approx(reward_jax, rel=1e-3, abs=1e-3)
        assert (term_host, trunc_host) == (term_jax, trunc_jax)
        if term_host or trunc_host:
            ends += 1
            (obs_host, info_host), (obs_jax, info_jax) = host.reset(), compiled.reset()
            np.testing.assert_array_equal(obs_host, obs_jax)  # the same compiled start
    assert ends >= 3  # several episodes, so several contexts of the set


def random_action(env: ContextualGymEnv, rng: np.random.Generator):
    if hasattr(env.action_space, "n"):
        return int(rng.integers(env.action_space.n))
    return rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32)


def test_same_seed_same_trajectory_with_host_noise():
    def run(seed: int) -> list[np.ndarray]:
        env = ContextualGymEnv("Acrobot", contexts={"torque_noise_max": 0.3})
        env.reset(seed=seed)
        return [env.step(i % 3)[0] for i in range(50)]

    first, again, other = run(1), run(1), run(2)
    np.testing.assert_array_equal(np.stack(first), np.stack(again))
    assert not np.allclose(np.stack(first), np.stack(other))


def test_noisy_context_observation_stays_compiled():
    noisy = ContextualGymEnv("CartPole", obs_context_features="all", obs_context_noise=0.1)
    assert type(noisy.backend) is JaxBackend
    clean = ContextualGymEnv("CartPole", obs_context_features="all")
    assert isinstance(clean.backend, ScalarBackend)


def test_bad_actions_are_refused_before_stepping():
    env = ContextualGymEnv("CartPole")
    env.reset(seed=0)
    for action in (2, -1, 0.5, "left"):
        with pytest.raises(ValueError, match="action must be an integer in \\[0, 2\\)"):
            env.step(action)
    pendulum = ContextualGymEnv("Pendulum")
    pendulum.reset(seed=0)
    for action in ([np.nan], [1.0, 1.0]):
        with pytest.raises(ValueError, match="finite float array of shape \\(1,\\)"):
            pendulum.step(np.asarray(action, np.float32))


def test_render_shows_the_host_state():
    env = ContextualGymEnv("CartPole", render_mode="rgb_array")
    env.reset(seed=0)
    start = env.render()
    for _ in range(8):
        env.step(1)
    moved = env.render()
    assert start.shape == moved.shape and not np.array_equal(start, moved)


def test_scalar_namespace_follows_jax_numpy():
    vector = scalar.stack([1.0, -2.0])
    assert vector + 1.0 == (2.0, -1.0) and 1.0 + vector == (2.0, -1.0)
    assert vector + vector == (2.0, -4.0) and 2 * vector == (2.0, -4.0)
    assert vector - vector == (0.0, 0.0) and vector / 2 == (0.5, -1.0)
    for x in (-3.0, 0.25, 3.0):
        assert scalar.clip(x, -1.0, 1.0) == float(jnp.clip(x, -1.0, 1.0))
    assert scalar.where(True, 1.0, 2.0) == 1.0 and scalar.where(False, 1.0, 2.0) == 2.0
    assert scalar.zeros((), bool) is False
    with pytest.raises(ValueError, match="only shape"):
        scalar.zeros((2,))
