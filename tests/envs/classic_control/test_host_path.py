"""The host (Python float) path of the classic-control envs agrees with their JAX transition, and the
single gymnasium env that steps on it follows the JAX backend's trajectories."""

from __future__ import annotations

import importlib.util
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
from contextrl.gymnasium.backends import HostBackend, JaxBackend, ScalarPhysics
from tests.helpers import ROOT

# Acrobot draws torque noise from the JAX key at every step, so it steps in JAX only.
ENVS = ("CartPole", "Pendulum", "MountainCar", "MountainCarContinuous")
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
        state, reward, done = env.host_transition(states[i].tolist(), action, context)
        where = f"{name} context {contexts[i]} state {states[i]} action {actions[i]}"
        np.testing.assert_allclose(state, next_states[i], rtol=1e-4, atol=1e-4, err_msg=where)
        np.testing.assert_allclose(reward, rewards[i], rtol=1e-4, atol=1e-4, err_msg=where)
        assert bool(done) == bool(terminated[i]), where
        observed = env.host_observe(state, context)
        np.testing.assert_allclose(observed, observations[i], rtol=1e-4, atol=1e-4, err_msg=where)
    # The sample reaches what it is meant to test: the episode-ending branch where there is one.
    if name in ("CartPole", "MountainCar"):
        assert np.asarray(terminated).any() and not np.asarray(terminated).all()


def test_steps_that_draw_random_numbers_stay_compiled():
    noisy_torque = ContextualGymEnv("Acrobot", contexts={"torque_noise_max": 0.3})
    assert type(noisy_torque.backend) is JaxBackend
    noisy = ContextualGymEnv("CartPole", obs_context_features="all", obs_context_noise=0.1)
    assert type(noisy.backend) is JaxBackend
    clean = ContextualGymEnv("CartPole", obs_context_features="all")
    assert type(clean.backend) is HostBackend
    assert type(clean.backend.simulator) is ScalarPhysics


def test_same_seed_same_trajectory_with_torque_noise():
    def run(seed: int) -> list[np.ndarray]:
        env = ContextualGymEnv("Acrobot", contexts={"torque_noise_max": 0.3})
        env.reset(seed=seed)
        return [env.step(i % 3)[0] for i in range(50)]

    first, again, other = run(1), run(1), run(2)
    np.testing.assert_array_equal(np.stack(first), np.stack(again))
    assert not np.allclose(np.stack(first), np.stack(other))


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


# The largest relative difference |a − b| / (1 + |b|) of an observation or reward over whole episodes
# allowed between the scalar host path and the compiled step; about twice the worst measured over
# 30 seeds × 3 episodes per row (benchmarks/results/host_path_divergence.md): Pendulum's chaotic
# swing-up amplifies float32 rounding, the others stay near it.
EPISODE_TOLERANCE = {
    "CartPole": 1e-4,
    "Pendulum": 0.1,
    "MountainCar": 1e-5,
    "MountainCarContinuous": 1e-4,
}
_spec = importlib.util.spec_from_file_location(
    "host_path_divergence", ROOT / "benchmarks" / "host_path_divergence.py"
)
divergence = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(divergence)


@pytest.mark.parametrize("name", ENVS)
def test_host_path_follows_the_compiled_step_over_whole_episodes(name):
    """One episode per row of the divergence benchmark (default, three features drawn ±20 %)."""
    for contexts, seed in [(None, 0), (divergence.drawn_contexts(name), 1)]:
        (host,), (compiled,) = (
            divergence.episodes(name, contexts, c, seed, 1) for c in (False, True)
        )
        assert len(host) == len(compiled)  # the episode ends at the same step, the same way
        assert host[-1][2:] == compiled[-1][2:]
        for field in (0, 1):  # observations, rewards
            a = np.array([s[field] for s in host])
            b = np.array([s[field] for s in compiled])
            assert np.max(np.abs(a - b) / (1 + np.abs(b))) <= EPISODE_TOLERANCE[name], contexts
