"""Contexts that change within an episode (``changes=``) through the gymnasium faces: the core's step
moves the context, and the observation and ``info["context"]`` show the value each step ran under."""

import functools

import gymnasium
import jax.numpy as jnp
import numpy as np
import pytest

import contextrl as crl

STEPS = 8
CHANGE_AT = 5  # steps 1…4 run under gravity 9.8, steps 5… under 20
BEFORE = CHANGE_AT - 1  # rows 0…BEFORE-1 are steps 1…CHANGE_AT-1
HEAVIER = crl.Piecewise({CHANGE_AT: {"gravity": 20.0}})


def heavier_from_the_step(step, context):
    return context.replace(gravity=jnp.where(step >= CHANGE_AT, 20.0, context.gravity))


def rollout(make, action, **kwargs):
    """Per step (1…STEPS): the observation, gravity shown last, and ``info["context"]["gravity"]``,
    of ``make``'s CartPole under ``action(t)``."""
    env = make("contextrl/CartPole-v0", obs_context_features=["gravity"], **kwargs)
    env.reset(seed=0)
    rows = [env.step(action(t)) for t in range(STEPS)]
    assert not any(np.any(np.logical_or(row[2], row[3])) for row in rows)
    return np.array([row[0] for row in rows]), np.array(
        [row[4]["context"]["gravity"] for row in rows]
    )


def single_rollout(**kwargs):
    return rollout(gymnasium.make, lambda t: t % 2, **kwargs)


def vector_rollout(**kwargs):
    make = functools.partial(gymnasium.make_vec, num_envs=2)
    return rollout(make, lambda t: np.full(2, t % 2), **kwargs)


def test_single_env_runs_the_changed_context_from_its_step_on():
    plain_obs, plain_gravity = single_rollout()
    obs, gravity = single_rollout(changes=HEAVIER)
    # the plain env steps CartPole's scalar physics on the host, to float32 rounding of the compiled
    np.testing.assert_allclose(obs[:BEFORE, :-1], plain_obs[:BEFORE, :-1], atol=1e-6)
    assert np.all(np.abs(obs[BEFORE:, :-1] - plain_obs[BEFORE:, :-1]).max(axis=1) > 1e-4)
    np.testing.assert_allclose(plain_gravity, 9.8)
    np.testing.assert_allclose(gravity, [9.8] * BEFORE + [20.0] * (STEPS - BEFORE), rtol=1e-6)
    np.testing.assert_allclose(obs[:, -1], gravity, rtol=1e-6)


def test_vector_env_runs_the_changed_context_from_its_step_on():
    # copy i of the vector env runs the global episodes the single env of copy_index=i runs
    plain = [single_rollout(copy_index=i, num_copies=2) for i in range(2)]
    plain_obs = np.stack([obs for obs, _ in plain], axis=1)
    changes = crl.StepFunction(heavier_from_the_step, ("gravity",))
    obs, gravity = vector_rollout(changes=changes)
    np.testing.assert_allclose(obs[:BEFORE], plain_obs[:BEFORE], atol=1e-6)
    assert np.all(np.abs(obs[BEFORE:, :, :-1] - plain_obs[BEFORE:, :, :-1]).max(axis=2) > 1e-4)
    expected = np.repeat([[9.8]] * BEFORE + [[20.0]] * (STEPS - BEFORE), 2, axis=1)
    np.testing.assert_allclose(gravity, expected, rtol=1e-6)
    np.testing.assert_allclose(obs[..., -1], gravity, rtol=1e-6)


@pytest.mark.parametrize("make", [gymnasium.make, gymnasium.make_vec])
@pytest.mark.parametrize(
    ("env_id", "changes", "message"),
    [
        ("CartPole", "gravity", "changes must be one of"),
        (
            "CartPole",
            crl.Piecewise({3: {"nope": 1.0}}),
            "Piecewise: unknown context feature 'nope'",
        ),
        (
            "CartPole",
            crl.Redraw(5, {"initial_state_lower": -0.1}),
            "Redraw: CartPole's feature 'initial_state_lower' cannot change mid-episode: it sets "
            "only the start state",
        ),
        (
            "LunarLander",
            crl.Piecewise({3: {"GRAVITY_Y": -5.0}}),
            "Piecewise: LunarLander is a host environment",
        ),
    ],
)
def test_a_change_that_cannot_run_is_refused_when_the_env_is_built(make, env_id, changes, message):
    with pytest.raises(crl.ContextError, match=message) as refused:
        make(f"contextrl/{env_id}-v0", changes=changes)
    assert "\n" not in str(refused.value)


def test_without_changes_the_single_env_keeps_the_host_path():
    env = gymnasium.make("contextrl/CartPole-v0")
    assert env.unwrapped.changes is None
    assert type(env.unwrapped.backend).__name__ == "HostBackend"
