"""The context model: declarations, validation with clear errors, conversion, distributions, selectors,
and what the agent gets to see."""

import math

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import contextrl as crl
from contextrl.context import ContextBase, ContextError, FromSet, Resample, context_type, feature
from contextrl.context.observation import ContextObservation

pytestmark = pytest.mark.quick


@context_type
class VehicleContext(ContextBase):
    """A test context with every kind of feature."""

    mass: float = feature(1.0, 0.5, 2.0, unit="t", doc="vehicle mass")
    wheels: int = feature(4, 2, 8, kind="int", doc="number of wheels")
    drive: int = feature(
        "rear",
        0,
        0,
        kind="categorical",
        choices=("front", "rear", "all"),
        doc="driven wheels",
        aliases=("drivetrain",),
    )


@pytest.fixture
def cartpole():
    return crl.make("CartPole")


# ---- declarations, validation, conversion ------------------------------------------------------


def test_declarations_are_read_from_the_fields(cartpole):
    length = cartpole.context_space.features["length"]
    assert (length.default, length.lower, length.upper, length.unit) == (0.5, 0.05, 5.0, "m")
    assert length.aliases == ("pole_length",) and length.affects == ("dynamics",)
    drive = VehicleContext.space.features["drive"]
    assert drive.kind == "categorical" and drive.bounds == (0, 2) and drive.default == 1


def test_aliases_and_replace(cartpole):
    ctx = cartpole.context(pole_length=0.8, update_interval=0.01, force_magnifier=20)
    assert float(ctx.length) == pytest.approx(0.8) and float(ctx.tau) == pytest.approx(0.01)
    assert float(ctx.replace(length=0.3).length) == pytest.approx(0.3)
    assert float(ctx.length) == pytest.approx(0.8)  # replace returns a copy


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"lenght": 1.0}, r"unknown context feature 'lenght'.*valid features: \['gravity'"),
        ({"length": 9.0}, r"length: value 9 is outside its bounds \[0.05, 5\]"),
        ({"length": float("nan")}, "length: value nan is not finite"),
        ({"gravity": float("inf")}, "gravity: value inf is not finite"),
        ({"length": "long"}, "length: expected a number, got str"),
        ({"length": True}, "length: expected a number, got a bool"),
        ({"length": [[0.5]]}, r"length: expected a scalar or a 1-D batch, got shape \(1, 1\)"),
        ({"length": 0.5, "pole_length": 0.6}, "length given twice"),
    ],
)
def test_bad_values_are_refused_and_change_nothing(cartpole, values, message):
    ctx = cartpole.context(length=0.7)
    with pytest.raises(ContextError, match=message):
        ctx.replace(**values)
    assert float(ctx.length) == pytest.approx(0.7)
    assert float(ctx.gravity) == pytest.approx(9.8)


def test_int_and_categorical_features():
    space = VehicleContext.space
    ctx = space.make(wheels=6, drivetrain="all")
    assert int(ctx.wheels) == 6 and int(ctx.drive) == 2
    assert space.to_dict(ctx) == {"mass": 1.0, "wheels": 6, "drive": "all"}
    with pytest.raises(ContextError, match=r"'awd' is not a valid choice; choose one of \['front'"):
        space.make(drive="awd")
    with pytest.raises(ContextError, match=r"wheels: expected an integer \(int\), got 4.5"):
        space.make(wheels=4.5)
    with pytest.raises(ContextError, match=r"drive: value 3 is outside its bounds \[0, 2\]"):
        space.make(drive=3)


def test_array_dict_and_gymnasium_round_trips(cartpole):
    space = cartpole.context_space
    batch = crl.sample(cartpole, {"length": crl.Uniform(0.2, 0.9)}, 5, jax.random.key(0))
    array = space.to_array(batch)
    assert array.shape == (5, len(space))
    again = space.from_array(array)
    np.testing.assert_array_equal(again.length, batch.length)
    assert space.to_dict(space.from_dict(space.to_dict(batch[2]))) == space.to_dict(batch[2])
    box = space.to_gymnasium()
    assert isinstance(box, gymnasium.spaces.Box) and box.contains(np.asarray(array[0]))
    with pytest.raises(ContextError, match="last axis has 8 entries"):
        space.from_array(jnp.zeros((5, 3)))


@pytest.mark.parametrize(
    ("declared", "message"),
    [
        (lambda: feature(5.0, 0.0, 1.0), "default 5.0 must lie inside finite bounds"),
        (lambda: feature(1.0, 0.0, math.inf), "must lie inside finite bounds"),
        (lambda: feature(0.5, 0.0, 1.0, affects=("colour",)), "affects must be a non-empty"),
        (lambda: feature("big", 0, 0, kind="categorical", choices=("small",)), "one of the choi"),
    ],
)
def test_feature_declaration_errors_name_the_feature(declared, message):
    """A declaration is checked when its context type is made, where the feature has its name."""
    with pytest.raises(ValueError, match=f"feature 'width' of Bad: .*{message}"):

        @context_type
        class Bad(ContextBase):
            width: float = declared()


# ---- distributions and sampling ---------------------------------------------------------------


def test_sample_draws_only_the_named_features(cartpole):
    batch = crl.sample(cartpole, {"pole_length": crl.Uniform(0.25, 0.75)}, 1000, jax.random.key(0))
    length = np.asarray(batch.length)
    assert length.shape == (1000,) and 0.25 <= length.min() and length.max() <= 0.75
    assert length.std() > 0.1
    np.testing.assert_array_equal(batch.gravity, np.full(1000, np.float32(9.8)))


def test_sampling_is_seeded_and_per_feature_stable(cartpole):
    spec = {"length": crl.Uniform(0.25, 0.75)}
    a = crl.sample(cartpole, spec, 64, jax.random.key(7))
    b = crl.sample(cartpole, spec, 64, jax.random.key(7))
    c = crl.sample(cartpole, {**spec, "gravity": crl.Normal(9.8, 1.0)}, 64, jax.random.key(7))
    d = crl.sample(cartpole, spec, 64, jax.random.key(8))
    np.testing.assert_array_equal(a.length, b.length)
    np.testing.assert_array_equal(a.length, c.length)  # adding a feature leaves the others alone
    assert not np.array_equal(a.length, d.length)


@pytest.mark.parametrize(
    ("distribution", "low", "high"),
    [
        (crl.Uniform(0.2, 0.4), 0.2, 0.4),
        (crl.LogUniform(0.1, 4.0), 0.1, 4.0),
        (crl.Normal(0.5, 2.0), 0.05, 5.0),  # truncated to the feature's bounds
        (crl.Normal(0.5, 0.1, low=0.45, high=0.6), 0.45, 0.6),
        (crl.RelativeUniform(0.5, 1.5), 0.25, 0.75),
        (crl.Scaled(2.2), 1.1, 1.1),
        (crl.Constant(0.3), 0.3, 0.3),
        (crl.Categorical([0.25, 0.5]), 0.25, 0.5),
    ],
)
def test_distributions_stay_in_their_support(cartpole, distribution, low, high):
    length = np.asarray(
        crl.sample(cartpole, {"length": distribution}, 2000, jax.random.key(1)).length
    )
    assert np.all(np.isfinite(length))
    assert length.min() >= np.float32(low) - 1e-6 and length.max() <= np.float32(high) + 1e-6


def test_log_uniform_is_uniform_in_log_space(cartpole):
    length = crl.sample(cartpole, {"length": crl.LogUniform(0.1, 1.0)}, 20000, jax.random.key(0))
    log_length = np.log10(np.asarray(length.length))
    assert np.mean(log_length < -0.5) == pytest.approx(0.5, abs=0.02)


def test_categorical_weights(cartpole):
    weighted = crl.Categorical([0.25, 0.5], weights=[0.9, 0.1])
    length = np.asarray(crl.sample(cartpole, {"length": weighted}, 5000, jax.random.key(0)).length)
    assert np.mean(length == np.float32(0.25)) == pytest.approx(0.9, abs=0.02)
    drive = crl.sample(
        VehicleContext, {"drive": crl.Categorical(["front", "all"])}, 100, jax.random.key(0)
    ).drive
    assert set(np.asarray(drive).tolist()) == {0, 2}


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ({"length": crl.Uniform(0.25, 7.0)}, r"length: Uniform reaches \[0.25, 7\], outside"),
        ({"length": crl.Uniform(0.8, 0.2)}, "Uniform is empty"),
        ({"length": crl.Uniform(0.2, math.nan)}, "high must be finite"),
        ({"length": crl.LogUniform(0.0, 1.0)}, "LogUniform needs 0 < low <= high"),
        ({"length": crl.Normal(0.5, -1.0)}, "Normal std must be > 0"),
        ({"length": crl.Scaled(20.0)}, r"Scaled\(20\) reaches \[10, 10\], outside"),
        (
            {"length": crl.RelativeUniform(0.1, 20)},
            r"RelativeUniform\(0.1, 20\) reaches \[0.05, 10\]",
        ),
        ({"length": crl.Categorical([])}, "Categorical needs at least one choice"),
        ({"length": crl.Categorical([0.3, 0.4], weights=[1.0])}, "2 choices but 1 weights"),
        ({"mass": crl.Uniform(0.6, 0.9)}, "unknown context feature 'mass'"),
    ],
)
def test_bad_distributions_are_refused_before_sampling(cartpole, spec, message):
    with pytest.raises(ContextError, match=message):
        crl.sample(cartpole, spec, 8, jax.random.key(0))


def test_sample_refuses_bad_sizes(cartpole):
    for n in (0, -3, 2.5, True):
        with pytest.raises(ContextError, match="n must be a positive integer"):
            crl.sample(cartpole, {}, n, jax.random.key(0))


def test_int_uniform_includes_both_ends():
    wheels = crl.sample(
        VehicleContext, {"wheels": crl.Uniform(2, 4)}, 500, jax.random.key(0)
    ).wheels
    assert set(np.asarray(wheels).tolist()) == {2, 3, 4}


# ---- context sets, selectors, resampling inside a compiled loop ----------------------------


def episode_contexts(contextual, episodes, key):
    """The context id and pole length of each of ``episodes`` episodes (5-step time limit)."""

    def body(state, _):
        state, ts = contextual.step(state, 0)
        return state, (ts.done, ts.info["next_context_id"], state.context.length)

    state, first = contextual.reset(key)
    _, (done, ids, lengths) = jax.jit(lambda s: jax.lax.scan(body, s, None, length=episodes * 5))(
        state
    )
    done = np.asarray(done)
    return (
        np.concatenate([[int(first.info["context_id"])], np.asarray(ids)[done][:-1]]),
        np.concatenate([[float(state.context.length)], np.asarray(lengths)[done][:-1]]),
    )


@pytest.fixture
def five_step_cartpole():
    # Short, fixed episodes: a 5-step limit and gravity/length that keep the pole up that long.
    return crl.make("CartPole", max_steps=5)


def test_round_robin_static_and_custom_selectors(five_step_cartpole):
    env = five_step_cartpole
    contexts = crl.sample(env, {"length": crl.Uniform(0.5, 1.0)}, 3, jax.random.key(0))
    ids, lengths = episode_contexts(crl.with_contexts(env, contexts), 7, jax.random.key(1))
    np.testing.assert_array_equal(ids, [0, 1, 2, 0, 1, 2, 0])
    np.testing.assert_allclose(lengths, np.asarray(contexts.length)[ids])
    ids, _ = episode_contexts(crl.with_contexts(env, contexts, "static"), 4, jax.random.key(1))
    np.testing.assert_array_equal(ids, [0, 0, 0, 0])
    backwards = crl.with_contexts(env, contexts, lambda key, episode, n: (n - 1 - episode) % n)
    ids, _ = episode_contexts(backwards, 4, jax.random.key(1))
    np.testing.assert_array_equal(ids, [2, 1, 0, 2])


def test_random_selector_is_seeded_by_the_key(five_step_cartpole):
    env = five_step_cartpole
    contexts = crl.sample(env, {"length": crl.Uniform(0.5, 1.0)}, 8, jax.random.key(0))
    random_env = crl.with_contexts(env, contexts, "random")
    np.random.seed(0)
    a, _ = episode_contexts(random_env, 30, jax.random.key(1))
    np.random.seed(1)  # the global NumPy RNG plays no part
    b, _ = episode_contexts(random_env, 30, jax.random.key(1))
    c, _ = episode_contexts(random_env, 30, jax.random.key(2))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert len(set(a.tolist())) >= 6


def test_resampling_draws_a_new_context_every_episode(five_step_cartpole):
    env = five_step_cartpole
    spec = {"length": crl.Uniform(0.5, 1.0)}
    ids, lengths = episode_contexts(crl.with_contexts(env, spec), 20, jax.random.key(3))
    assert np.all(ids == -1)
    assert len(np.unique(lengths)) == 20 and lengths.min() >= 0.5 and lengths.max() <= 1.0


def test_selector_and_set_errors(cartpole):
    contexts = crl.sample(cartpole, {"length": crl.Uniform(0.5, 1.0)}, 3, jax.random.key(0))
    with pytest.raises(ContextError, match=r"unknown context selector 'shuffle'; choose one of"):
        crl.with_contexts(cartpole, contexts, "shuffle")
    with pytest.raises(ContextError, match="static selector index 5 is outside the set of 3"):
        FromSet(contexts, crl.context.Static(5))
    with pytest.raises(ContextError, match="expected PendulumContext, got CartPoleContext"):
        crl.with_contexts(crl.make("Pendulum"), contexts)
    with pytest.raises(ContextError, match="needs at least one feature"):
        Resample(cartpole.context_space, {})
    with pytest.raises(ContextError, match=r"contexts\[0\]: expected a dict of feature values"):
        crl.with_contexts(cartpole, [0.5, 0.6])
    # A list of values where one value belongs: named, not reported as another feature's shape.
    one_value = r"length takes one value per context, got 2; list one dict per context instead"
    with pytest.raises(ContextError, match=r"contexts\[1\]: " + one_value):
        crl.with_contexts(cartpole, [{"length": 0.5}, {"length": [0.5, 0.6]}])
    with pytest.raises(ContextError, match=r"^contexts: " + one_value):
        crl.with_contexts(cartpole, {"length": [0.5, 0.6]})


def test_a_dict_of_values_is_one_context(cartpole):
    contextual = crl.with_contexts(cartpole, {"length": 0.9})
    state, ts = contextual.reset(jax.random.key(0))
    assert float(state.context.length) == pytest.approx(0.9) and int(ts.info["context_id"]) == 0


# ---- what the agent sees ------------------------------------------------------------------------


def test_hidden_observation_is_the_original(cartpole):
    ctx = cartpole.context(length=1.3)
    state, ts = cartpole.reset(jax.random.key(0), ctx)
    np.testing.assert_array_equal(ts.obs, state.physics)
    assert cartpole.observation_space.shape == (4,)


def test_visible_features_all_subset_varying_and_normalised(cartpole):
    ctx = cartpole.context(length=1.3, gravity=5.0)
    key = jax.random.key(0)
    everything = crl.make("CartPole", obs_context_features="all")
    obs = everything.reset(key, ctx)[1].obs
    assert obs.shape == (12,) and everything.observation_space.contains(obs)
    np.testing.assert_allclose(obs[4:], cartpole.context_space.to_array(ctx))

    subset = crl.make("CartPole", obs_context_features=["pole_length"], obs_context_normalize=True)
    obs = subset.reset(key, ctx)[1].obs
    assert obs.shape == (5,)
    assert float(obs[4]) == pytest.approx((1.3 - 0.05) / (5.0 - 0.05), rel=1e-5)

    contexts = crl.sample(cartpole, {"tau": crl.Uniform(0.01, 0.03)}, 4, key)
    varying = crl.make("CartPole", obs_context_features="varying", contexts=contexts)
    assert varying.obs_context.features == ("tau",)


def test_noisy_context_changes_with_the_key_and_stays_in_bounds(cartpole):
    env = crl.make("CartPole", obs_context_features=["length"], obs_context_noise=0.5)
    ctx = cartpole.context(length=4.9)
    values = np.array([float(env.reset(jax.random.key(i), ctx)[1].obs[4]) for i in range(200)])
    assert values.std() > 0.5 and values.max() <= 5.0 and values.min() >= 0.05
    again = np.array([float(env.reset(jax.random.key(i), ctx)[1].obs[4]) for i in range(200)])
    np.testing.assert_array_equal(values, again)
    assert np.mean(values) == pytest.approx(4.9 * 0.85, rel=0.15)


def test_bad_observation_options_are_refused(cartpole):
    with pytest.raises(ContextError, match="unknown context observation mode 'some'"):
        crl.make("CartPole", obs_context_features="some")
    with pytest.raises(ContextError, match="unknown context feature 'mass'"):
        crl.make("CartPole", obs_context_features=["mass"])
    with pytest.raises(ContextError, match='"varying" needs the context set'):
        crl.make("CartPole", obs_context_features="varying")
    with pytest.raises(ContextError, match="noise must be >= 0"):
        ContextObservation.build(cartpole.context_space, "all", noise=-0.1)
    with pytest.raises(ContextError, match="noise must be a finite number"):
        ContextObservation.build(cartpole.context_space, "all", noise=math.nan)


def test_registry_errors_and_carl_ids():
    assert crl.spec("CARLPendulum").id == "Pendulum"
    with pytest.raises(KeyError, match=r"unknown environment 'CartPol'\. Did you mean"):
        crl.make("CartPol")
    with pytest.raises(ValueError, match="max_steps must be a positive integer"):
        crl.make("CartPole", max_steps=0)
    with pytest.raises(ValueError, match=r"at most 2,147,483,647 \(the step counter is int32\)"):
        crl.make("CartPole", max_steps=10**12)
    assert crl.make("CartPole", max_steps=2**31 - 1).max_steps == 2**31 - 1


def test_a_batched_value_makes_a_batch(cartpole):
    batch = cartpole.context(length=[0.3, 0.4, 0.5])
    assert batch.batch_shape == (3,) and len(batch) == 3
    np.testing.assert_allclose(batch.gravity, [9.8, 9.8, 9.8])
    with pytest.raises(ContextError, match="different batch shapes"):
        cartpole.context(length=[0.3, 0.4], gravity=[9.8, 9.8, 9.8])


def test_demo_controller_return_depends_on_the_pole_length(cartpole):
    from contextrl.demo import episode_returns

    contexts = cartpole.context(length=np.repeat(np.float32([0.05, 0.5]), 16))
    returns = np.asarray(
        jax.jit(episode_returns, static_argnums=0)(cartpole, contexts, jax.random.key(0))
    )
    assert returns[:16].mean() < 200 and returns[16:].mean() == 500.0


def test_a_context_at_its_bounds_passes_validation_again(cartpole):
    """Bounds like 0.2 are not exact in float32; a stored bound value must still be valid."""
    edge = cartpole.context(tau=0.2, masspole=0.01, initial_state_upper=0.2)
    cartpole.context_space.check(edge)
    FromSet(cartpole.context_space.stack([edge]))
    with pytest.raises(
        ContextError, match=r"tau: value 0.2001 is outside its bounds \[0.002, 0.2\]"
    ):
        cartpole.context(tau=0.2001)


# ---- coherence across features --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("env_id", "values", "names"),
    [
        ("MountainCar", {"goal_position": 0.9}, ("goal_position", "max_position")),
        ("MountainCarContinuous", {"max_position": 0.3}, ("goal_position", "max_position")),
        (
            "MountainCar",
            {"min_position": -0.7, "min_position_start": -1.0},
            ("min_position", "min_position_start"),
        ),
        (
            "MountainCar",
            {"max_position": 0.2, "goal_position": 0.1, "max_position_start": 0.4},
            ("max_position_start", "max_position"),
        ),
        (
            "Acrobot",
            {"LINK_LENGTH_1": 0.3, "LINK_LENGTH_2": 0.5},
            ("LINK_LENGTH_1", "LINK_LENGTH_2"),
        ),
    ],
)
def test_incoherent_contexts_are_refused_naming_both_features(env_id, values, names):
    env = crl.make(env_id)
    pattern = ".*".join(names)
    with pytest.raises(ContextError, match=pattern):
        env.context(**values)
    with pytest.raises(ContextError, match=pattern):  # and as a set member, before anything runs
        crl.with_contexts(env, [values])


def test_a_spec_that_can_draw_an_incoherent_context_is_refused_up_front():
    mountain_car = crl.make("MountainCar")
    with pytest.raises(ContextError, match=r"goal_position in \[0.3, 0.8\], max_position in \[0.6"):
        crl.sample(mountain_car, {"goal_position": crl.Uniform(0.3, 0.8)}, 8, jax.random.key(0))
    with pytest.raises(ContextError, match="goal_position <= max_position"):
        crl.with_contexts(mountain_car, {"max_position": crl.Uniform(0.3, 1.0)})  # resampled
    # Ranges whose every corner is coherent draw only coherent contexts.
    spec = {"goal_position": crl.Uniform(0.0, 0.5), "max_position": crl.Uniform(0.5, 1.0)}
    drawn = crl.sample(mountain_car, spec, 512, jax.random.key(1))
    assert np.all(np.asarray(drawn.goal_position) <= np.asarray(drawn.max_position))
    acrobot = crl.make("Acrobot")
    with pytest.raises(ContextError, match="LINK_LENGTH_1 \\+ LINK_LENGTH_2 > 1"):
        crl.sample(
            acrobot,
            {"LINK_LENGTH_1": crl.Uniform(0.1, 2.0), "LINK_LENGTH_2": crl.Scaled(0.5)},
            4,
            jax.random.key(0),
        )
