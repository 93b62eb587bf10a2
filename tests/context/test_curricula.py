"""Curricula over contexts: parameters that are data (no new compile), and SPaCE's, ADR's and PLR's
update rules checked against hand computations; then PPO trained under each."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import contextrl as crl
from contextrl.agents import dqn, ppo, sac
from contextrl.agents.validation import ConfigError
from contextrl.context import ContextError, Resample, Uniform
from contextrl.context.curricula import ADR, PLR, EdgeSampler, Feedback, SPaCE, WeightedSet
from contextrl.core.contextual import ContextualEnv

ENV = crl.make("CartPole")
SPACE = ENV.context_space
POOL = crl.sample(ENV, {"length": Uniform(0.2, 2.0)}, 6, jax.random.key(3))


def feedback(n, returns=None, episodes=None, scores=None, start_values=None):
    nan = np.full(n, np.nan, np.float32)
    return Feedback(
        returns=jnp.asarray(nan if returns is None else returns, jnp.float32),
        episodes=jnp.asarray(np.zeros(n) if episodes is None else episodes, jnp.int32),
        scores=jnp.asarray(nan if scores is None else scores, jnp.float32),
        start_values=jnp.asarray(nan if start_values is None else start_values, jnp.float32),
    )


@pytest.mark.quick
def test_distribution_parameters_are_data_one_compile_changes_what_is_drawn():
    traces = []

    @jax.jit
    def lengths(low, high, weights):
        traces.append(1)
        ranged = ContextualEnv(ENV, Resample(SPACE, {"length": Uniform(low, high)}))
        weighted = ContextualEnv(ENV, WeightedSet(POOL, weights))
        first, _ = ranged.reset_copies(jax.random.key(0), 256)
        second, _ = weighted.reset_copies(jax.random.key(0), 256)
        return first.context.length, second.context_id

    narrow, only_first = lengths(0.5, 0.6, jnp.asarray([1.0, 0, 0, 0, 0, 0]))
    wide, only_last = lengths(1.0, 3.0, jnp.asarray([0, 0, 0, 0, 0, 1.0]))
    assert len(traces) == 1  # the second call reused the compiled program
    assert 0.5 <= narrow.min() and narrow.max() <= 0.6
    assert 1.0 <= wide.min() and wide.max() <= 3.0 and wide.max() - wide.min() > 1.5
    assert set(np.asarray(only_first)) == {0} and set(np.asarray(only_last)) == {5}
    # draws follow the weights: member 1 three times as often as member 0, the zero ones never
    weights = jnp.asarray([1.0, 3.0, 0, 0, 0, 0])
    draws = jax.vmap(lambda k: WeightedSet(POOL, weights)(k, 0)[1])(
        jax.random.split(jax.random.key(5), 8192)
    )
    assert set(np.asarray(draws)) == {0, 1}
    assert np.mean(np.asarray(draws) == 1) == pytest.approx(0.75, abs=0.02)  # sd 0.005


def adr(**options):
    settings = dict(widen_above=100.0, narrow_below=20.0, buffer_size=2, delta=0.1)
    return ADR(SPACE, {"length": (0.1, 2.1), "gravity": (5.0, 15.0)}, **{**settings, **options})


@pytest.mark.quick
def test_adr_moves_an_edge_only_on_a_full_buffer_past_a_threshold_never_past_the_bounds():
    curriculum = adr()
    state = curriculum.init()  # both ranges start at the default: length 0.5, gravity 9.8
    np.testing.assert_allclose(state.low, [0.5, 9.8])
    # edges: length low, length high, gravity low, gravity high
    state = curriculum.update(state, feedback(4, [150, 150, 10, 50], [1, 2, 2, 2]))
    # length low: 1 of 2 returns (waits); length high: widen by 0.1 × 2.0; gravity low: narrow
    # (clipped at the other edge); gravity high: between the thresholds, no move.
    np.testing.assert_allclose(state.low, [0.5, 9.8], rtol=1e-6)
    np.testing.assert_allclose(state.high, [0.7, 9.8], rtol=1e-6)
    np.testing.assert_allclose(state.buffer_count, [1, 0, 0, 0])
    state = curriculum.update(state, feedback(4, [110, np.nan, np.nan, np.nan], [1, 0, 0, 0]))
    np.testing.assert_allclose(state.low, [0.3, 9.8], rtol=1e-6)  # mean (150 + 110) / 2 ≥ 100
    for _ in range(40):  # always widening: stops at the outer bounds
        state = curriculum.update(state, feedback(4, [500] * 4, [2] * 4))
    np.testing.assert_allclose(state.low, [0.1, 5.0], rtol=1e-6)
    np.testing.assert_allclose(state.high, [2.1, 15.0], rtol=1e-6)


@pytest.mark.quick
def test_adr_pins_one_edge_with_its_id_and_draws_inside_the_ranges_otherwise():
    low, high = jnp.asarray([0.3, 8.0]), jnp.asarray([0.9, 12.0])
    keys = jax.random.split(jax.random.key(1), 400)
    names = ("length", "gravity")
    pinned = jax.vmap(EdgeSampler(SPACE, names, low, high, 1.0), (0, None))(keys, 0)
    context, ids = pinned
    values = np.stack([context.length, context.gravity], 1)
    edges = np.stack([low, high], 1)  # (feature, side)
    for value, edge in zip(values, np.asarray(ids), strict=True):
        assert value[edge // 2] == pytest.approx(float(edges[edge // 2, edge % 2]))
    assert set(np.asarray(ids)) == {0, 1, 2, 3}
    context, ids = jax.vmap(EdgeSampler(SPACE, names, low, high, 0.0), (0, None))(keys, 0)
    assert set(np.asarray(ids)) == {-1}
    assert 0.3 <= context.length.min() and context.length.max() <= 0.9
    assert np.all(np.asarray(context.masscart) == SPACE.features["masscart"].default)


@pytest.mark.quick
def test_space_grows_in_value_order_only_once_the_value_has_settled():
    curriculum = SPaCE(POOL, initial=2, step=2, threshold=0.05)
    state = curriculum.init()
    values = jnp.asarray([1.0, 5.0, 3.0, 4.0, 2.0, 6.0])
    state = curriculum.update(state, feedback(6, start_values=values))
    assert int(state.size) == 2  # nothing to compare with yet
    np.testing.assert_array_equal(state.active, [0, 1, 0, 0, 0, 1])  # the two highest
    state = curriculum.update(state, feedback(6, start_values=values * 1.5))
    assert int(state.size) == 2  # the active mean moved by 50 %
    state = curriculum.update(state, feedback(6, start_values=values * 1.52))
    assert int(state.size) == 4  # moved by 1.3 %: settled, the next two by value join
    np.testing.assert_array_equal(state.active, [0, 1, 1, 1, 0, 1])
    np.testing.assert_allclose(curriculum.weights(state), np.asarray(state.active) / 4)


@pytest.mark.quick
def test_plr_replays_by_the_rank_rule_brings_stale_contexts_back_and_mixes_in_new_ones():
    curriculum = PLR(POOL, replay_probability=0.5, temperature=0.5, staleness=0.0)
    state = curriculum.init()
    np.testing.assert_allclose(curriculum.weights(state), np.full(6, 1 / 6))  # nothing played
    scores = [0.5, 2.0, 1.0, np.nan, np.nan, np.nan]  # three played this rollout
    state = curriculum.update(state, feedback(6, scores=scores))
    # ranks 3, 1, 2 → (1/rank)^(1/0.5): 1/9, 1, 1/4; half the mass, the other half on the unplayed
    by_rank = np.asarray([1 / 9, 1, 1 / 4])
    expected = np.concatenate([0.5 * by_rank / by_rank.sum(), np.full(3, 0.5 / 3)])
    np.testing.assert_allclose(curriculum.weights(state), expected, rtol=1e-5)
    stale = PLR(POOL, temperature=0.5, staleness=1.0)  # weights by updates since last played
    state = stale.update(stale.init(), feedback(6, scores=[1.0] * 6))
    for _ in range(3):  # members 1-5 keep being played, member 0 does not
        state = stale.update(state, feedback(6, scores=[np.nan] + [1.0] * 5))
    weights = np.asarray(stale.weights(state))
    assert weights[0] == pytest.approx(4 / 9) and weights[1] == pytest.approx(1 / 9)


@pytest.mark.quick
def test_bad_curriculum_parameters_are_refused_by_name():
    with pytest.raises(ContextError, match="initial must be an integer in"):
        SPaCE(POOL, initial=7)
    with pytest.raises(ContextError, match="temperature must be a number"):
        PLR(POOL, temperature=float("nan"))
    with pytest.raises(ContextError, match="narrow_below .* must be below widen_above"):
        adr(narrow_below=200.0)
    with pytest.raises(ContextError, match="outside the feature's bounds"):
        ADR(SPACE, {"length": (-1.0, 2.0)}, widen_above=1, narrow_below=0)
    with pytest.raises(ContextError, match="a pool needs at least 2"):
        PLR(POOL[:1])


CONFIG = ppo.PPOConfig(total_timesteps=8 * 32 * 5, num_envs=8, num_steps=32)


def test_ppo_under_plr_and_adr_carries_the_curriculum_through_the_compiled_loop():
    result = jax.jit(ppo.make_train(CONFIG, ENV, PLR(POOL)))(jax.random.key(0))
    weights = np.asarray(result.metrics["curriculum"]["weights"])
    assert weights.shape == (5, 6)
    np.testing.assert_allclose(weights.sum(1), 1.0, rtol=1e-5)
    np.testing.assert_allclose(weights[0], 1 / 6)  # before any rollout: all new
    assert np.ptp(weights[-1]) > 0.1  # scores from the rollouts now rank the members
    played = np.asarray(result.metrics["episodes"]["context_id"])
    assert set(played[played > -2]) <= set(range(6))
    # widen whenever an edge has one return at or above 0 (every CartPole return): ranges grow
    always = ADR(SPACE, {"length": (0.1, 2.1)}, widen_above=0.0, narrow_below=-1.0, buffer_size=1)
    result = jax.jit(ppo.make_train(CONFIG, ENV, always))(jax.random.key(0))
    low = np.asarray(result.metrics["curriculum"]["low"])[:, 0]
    high = np.asarray(result.metrics["curriculum"]["high"])[:, 0]
    assert low[0] == pytest.approx(0.5) and high[0] == pytest.approx(0.5)
    assert np.all(np.diff(low) <= 0) and np.all(np.diff(high) >= 0) and high[-1] > 0.5


def test_a_curriculum_chooses_its_own_contexts():
    train = ppo.make_train(CONFIG, ENV, SPaCE(POOL))
    with pytest.raises(ConfigError, match="trains under a curriculum"):
        train(jax.random.key(0), POOL)


def test_off_policy_loops_carry_space_and_adr_and_refuse_plr():
    """DQN and SAC under a curriculum: a logging period is a rollout. SPaCE with a threshold no change
    exceeds grows by its step once the learner's start values have a mean, which they have only if
    the loop hands them over; ADR that widens on any return at an edge only widens."""
    config = dqn.DQNConfig(
        total_timesteps=8 * 25 * 5 + 64,
        num_envs=8,
        learning_starts=64,
        log_every=200,
        batch_size=16,
        hidden_sizes=(16,),
        variant="concat_varying",
    )
    growing = SPaCE(POOL, initial=2, step=2, threshold=1e9)
    result = jax.jit(dqn.make_train(config, ENV, growing))(jax.random.key(0))
    sizes = np.asarray(result.metrics["curriculum"]["size"])
    np.testing.assert_array_equal(sizes, [2, 2, 4, 6, 6])  # the first update has no last value
    weights = np.asarray(result.metrics["curriculum"]["weights"])
    np.testing.assert_array_equal(weights[0], [0.5, 0.5, 0, 0, 0, 0])
    always = ADR(SPACE, {"length": (0.1, 2.1)}, widen_above=0.0, narrow_below=-1.0, buffer_size=1)
    result = jax.jit(dqn.make_train(config, ENV, always))(jax.random.key(0))
    high = np.asarray(result.metrics["curriculum"]["high"])[:, 0]
    assert high[0] == pytest.approx(0.5) and np.all(np.diff(high) >= 0) and high[-1] > 0.55
    with pytest.raises(ConfigError, match="plr scores contexts by the positive advantage"):
        dqn.make_train(config, ENV, PLR(POOL))

    pendulum = crl.make("Pendulum")
    pool = crl.sample(pendulum, {"g": Uniform(5.0, 15.0)}, 4, jax.random.key(3))
    warmup, rows = (
        {"learning_starts": 200, "num_envs": 2},
        {"total_timesteps": 500, "log_every": 100},
    )
    config = sac.SACConfig(
        **warmup, **rows, hidden_sizes=(8,), batch_size=16, variant="concat_varying"
    )
    result = jax.jit(sac.make_train(config, pendulum, SPaCE(pool, threshold=1e9)))(
        jax.random.key(0)
    )
    np.testing.assert_array_equal(result.metrics["curriculum"]["size"], [1, 1, 2])
    with pytest.raises(ContextError, match="expected PendulumContext, got CartPoleContext"):
        sac.make_train(config, pendulum, SPaCE(POOL))
