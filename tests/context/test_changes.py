"""Contexts that change within an episode (``contextrl.context.changes``), through the core's step."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import contextrl as crl

STEPS = 12
CHANGE_AT = 5


def rollout(cenv, key=0, steps=STEPS):
    """Per step (1…steps): the observation and the state's gravity, under alternating pushes."""
    state, _ = cenv.reset(jax.random.key(key))

    def body(state, t):
        state, timestep = cenv.step(state, t % 2)
        return state, (timestep.obs, state.context.gravity, timestep.done)

    _, (obs, gravity, done) = jax.jit(
        lambda s: jax.lax.scan(body, s, jnp.arange(steps, dtype=jnp.int32))
    )(state)
    assert not np.any(done), "the episode must last the whole rollout"
    return np.asarray(obs), np.asarray(gravity)


@pytest.fixture(scope="module")
def cartpole():
    return crl.make("CartPole")


def test_piecewise_changes_the_dynamics_from_its_step_on(cartpole):
    contexts = [cartpole.default_context()]
    plain_obs, plain_gravity = rollout(crl.with_contexts(cartpole, contexts))
    changes = crl.Piecewise({CHANGE_AT: {"gravity": 20.0}})
    obs, gravity = rollout(crl.with_contexts(cartpole, contexts, changes=changes))
    before = CHANGE_AT - 1  # rows 0…CHANGE_AT-2 are steps 1…CHANGE_AT-1
    np.testing.assert_array_equal(obs[:before], plain_obs[:before])
    assert np.all(np.any(obs[before:] != plain_obs[before:], axis=1))
    np.testing.assert_allclose(plain_gravity, 9.8)
    np.testing.assert_allclose(gravity, [9.8] * before + [20.0] * (STEPS - before))


def test_an_observation_of_the_context_shows_the_new_value(cartpole):
    seen = cartpole.with_obs_context(["gravity"])
    changes = crl.Piecewise({CHANGE_AT: {"gravity": 20.0}})
    obs, gravity = rollout(crl.with_contexts(seen, [seen.default_context()], changes=changes))
    np.testing.assert_allclose(obs[:, -1], gravity)


def test_a_later_piece_replaces_an_earlier_one(cartpole):
    changes = crl.Piecewise({8: {"gravity": 2.0}, 3: {"gravity": 20.0}})
    _, gravity = rollout(crl.with_contexts(cartpole, [cartpole.default_context()], changes=changes))
    np.testing.assert_allclose(gravity, [9.8] * 2 + [20.0] * 5 + [2.0] * 5)


def test_redraw_draws_every_n_steps_and_the_same_key_repeats_it(cartpole):
    changes = crl.Redraw(4, {"gravity": crl.Uniform(5.0, 15.0)})
    cenv = crl.with_contexts(cartpole, [cartpole.default_context()], changes=changes)
    obs, gravity = rollout(cenv, key=3)
    again_obs, again_gravity = rollout(cenv, key=3)
    np.testing.assert_array_equal(obs, again_obs)
    np.testing.assert_array_equal(gravity, again_gravity)
    np.testing.assert_allclose(gravity[:3], 9.8)
    for start in (3, 7, 11):  # steps 4, 8 and 12 draw; the value holds until the next draw
        assert np.all(gravity[start : start + 4] == gravity[start])
        assert 5.0 <= gravity[start] <= 15.0
    assert len({gravity[3], gravity[7], gravity[11]}) == 3
    _, other_gravity = rollout(cenv, key=4)
    assert not np.array_equal(gravity, other_gravity)


def test_random_walk_stays_in_its_range_and_copies_walk_their_own_way(cartpole):
    changes = crl.RandomWalk({"gravity": 0.5}, ranges={"gravity": (9.0, 10.5)})
    cenv = crl.with_contexts(cartpole, [cartpole.default_context()], changes=changes)
    _, gravity = rollout(cenv)
    assert np.all((gravity >= 9.0) & (gravity <= 10.5))
    assert len(np.unique(gravity)) > STEPS // 2
    state, _ = cenv.reset_copies(jax.random.key(0), 4)
    state, _ = jax.jit(cenv.step_copies)(state, jnp.zeros(4, jnp.int32))
    assert len(np.unique(np.asarray(state.context.gravity))) == 4


def test_step_function_sets_only_its_features(cartpole):
    def heavier(step, context):
        return context.replace(gravity=9.8 + step, length=0.9)

    changes = crl.StepFunction(heavier, ("gravity",))
    cenv = crl.with_contexts(cartpole, [cartpole.default_context()], changes=changes)
    state, _ = cenv.reset(jax.random.key(0))
    state, _ = jax.jit(cenv.step)(state, jnp.int32(0))
    state, _ = jax.jit(cenv.step)(state, jnp.int32(1))
    assert float(state.context.gravity) == pytest.approx(11.8)
    assert float(state.context.length) == pytest.approx(0.5)


def test_a_new_episode_starts_from_its_own_context(cartpole):
    changes = crl.Piecewise({1: {"gravity": 20.0}})
    cenv = crl.with_contexts(cartpole, [cartpole.default_context()], changes=changes)
    state, _ = cenv.reset(jax.random.key(0))
    state, _ = cenv.step(state, jnp.int32(0))
    assert float(state.context.gravity) == 20.0
    restarted, _ = cenv.restart(state)
    assert float(restarted.context.gravity) == pytest.approx(9.8)


@pytest.mark.parametrize(
    ("env_id", "changes", "message"),
    [
        (
            "CartPole",
            crl.Redraw(5, {"initial_state_lower": crl.Uniform(-0.1, -0.05)}),
            "Redraw: CartPole's feature 'initial_state_lower' cannot change mid-episode: it sets "
            "only the start state",
        ),
        (
            "MountainCar",
            crl.Piecewise({3: {"min_position_start": -0.5}}),
            "'min_position_start' cannot change mid-episode",
        ),
        (
            "Pendulum",
            crl.RandomWalk({"initial_angle_max": 0.1}),
            "'initial_angle_max' cannot change mid-episode",
        ),
        (
            "Platformer",
            crl.Piecewise({3: {"noise_seed": 5}}),
            "'noise_seed' cannot change mid-episode: it sets the level's layout",
        ),
        (
            "Platformer",
            crl.StepFunction(lambda step, context: context, ("gravity",)),
            "'gravity' cannot change mid-episode: the level's gaps",
        ),
    ],
)
def test_a_feature_that_cannot_act_mid_episode_is_refused(env_id, changes, message):
    env = crl.make(env_id)
    with pytest.raises(crl.ContextError, match=message.replace("(", r"\(")):
        crl.with_contexts(env, [env.default_context()], changes=changes)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        (crl.Redraw(0, {"gravity": crl.Uniform(5, 15)}), "Redraw: every must be a positive"),
        (crl.Redraw(2.5, {"gravity": crl.Uniform(5, 15)}), "got 2.5"),
        (crl.Redraw(5, {"gravity": crl.Uniform(5, float("nan"))}), "Redraw: spec: gravity"),
        (crl.Redraw(5, {}), "Redraw: spec must be a non-empty mapping"),
        (crl.Redraw(5, {"nope": 1.0}), "Redraw: unknown context feature 'nope'"),
        (crl.RandomWalk({"gravity": float("nan")}), r"step_size\['gravity'\] must be finite"),
        (crl.RandomWalk({"gravity": float("inf")}), "must be finite, got inf"),
        (crl.RandomWalk({"gravity": "big"}), "must be a number, got 'big'"),
        (crl.RandomWalk({"gravity": -0.1}), "must be > 0"),
        (crl.RandomWalk({"gravity": 0.1}, {"gravity": (5, 500)}), "inside gravity's bounds"),
        (crl.RandomWalk({"gravity": 0.1}, {"length": (0.2, 0.4)}), "does not walk"),
        (crl.Piecewise({0: {"gravity": 5.0}}), "a key of values must be a positive integer"),
        (crl.Piecewise({3: {"gravity": float("inf")}}), r"values\[3\]: gravity: value inf"),
        (crl.Piecewise({3: {"gravity": "heavy"}}), r"values\[3\]: gravity: expected a number"),
        (crl.StepFunction("fn", ("gravity",)), "fn must be callable"),
        (crl.StepFunction(lambda s, c: c, "gravity"), "expected feature names"),
        ("gravity", "changes must be one of"),
    ],
)
def test_bad_parameters_are_refused(cartpole, changes, message):
    with pytest.raises(crl.ContextError, match=message):
        crl.with_contexts(cartpole, [cartpole.default_context()], changes=changes)


def test_no_changes_leaves_the_step_as_it_was(cartpole):
    contexts = [cartpole.default_context()]
    plain = crl.with_contexts(cartpole, contexts)
    state, _ = plain.reset(jax.random.key(0))
    assert plain.changes is None
    unchanged = crl.ContextualEnv(cartpole, plain.provider, changes=None)
    assert str(jax.make_jaxpr(plain.step)(state, 0)) == str(
        jax.make_jaxpr(unchanged.step)(state, 0)
    )
