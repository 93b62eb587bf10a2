"""Statistics against hand-computed values; seeded, design-aware bootstrap behaviour."""

import numpy as np
import pytest
import scipy.stats

from contextrl.analysis import intervals, metrics

pytestmark = pytest.mark.quick

# 3 runs × 3 contexts; per-context means are [1, 30, 400].
SCORES = np.array([[0.0, 10.0, 100.0], [1.0, 20.0, 200.0], [2.0, 60.0, 900.0]])


def test_aggregates_match_hand_computation():
    assert metrics.aggregate_mean(SCORES) == pytest.approx(431 / 3)
    assert metrics.aggregate_median(SCORES) == pytest.approx(30.0)
    # sorted: 0 1 2 10 20 60 100 200 900; floor(9/4) = 2 cut from each end -> 2 10 20 60 100
    assert metrics.aggregate_iqm(SCORES) == pytest.approx(38.4)
    assert metrics.aggregate_iqm(SCORES) == pytest.approx(
        scipy.stats.trim_mean(SCORES, 0.25, axis=None)
    )


def test_optimality_gaps():
    # min(scores, 50) sums to 0+10+50+1+20+50+2+50+50 = 233 over 9 values
    assert metrics.aggregate_optimality_gap(SCORES, threshold=50) == pytest.approx(50 - 233 / 9)
    # optimal per context [5, 40, 400] vs achieved means [1, 30, 400]: gaps 4, 10, 0
    assert metrics.context_optimality_gap(SCORES, [5.0, 40.0, 400.0]) == pytest.approx(14 / 3)
    np.testing.assert_allclose(metrics.per_context_gap(SCORES, [5.0, 40.0, 400.0]), [4, 10, 0])
    with pytest.raises(ValueError, match="cover 2 contexts"):
        metrics.context_optimality_gap(SCORES, [1.0, 2.0])


def test_probability_of_improvement_counts_ties_half():
    x, y = np.array([[1.0], [3.0]]), np.array([[2.0], [3.0]])
    # pairs: 1<2, 1<3, 3>2, 3=3 -> (1 + 0.5) / 4
    assert metrics.probability_of_improvement(x, y) == pytest.approx(0.375)
    assert metrics.probability_of_improvement(y, x) == pytest.approx(0.625)


def test_fraction_solved():
    assert metrics.fraction_solved(SCORES, 100.0) == pytest.approx(3 / 9)


@pytest.mark.parametrize("bad", [[[np.nan, 1.0]], [[np.inf]], np.zeros((0, 3)), 4.0])
def test_bad_scores_refused(bad):
    with pytest.raises(ValueError):
        metrics.aggregate_mean(bad)


def test_a_stack_of_matrices_gives_one_value_per_matrix():
    """The bootstrap evaluates its replicates as one stack: each value must be the matrix's own."""
    stack = np.stack([SCORES, SCORES[::-1] * 2.0, SCORES + 1.0])
    masked = np.ma.MaskedArray(stack, np.zeros_like(stack, bool))
    masked[1, 0, 2] = np.ma.masked
    for metric in (metrics.aggregate_mean, metrics.aggregate_median, metrics.aggregate_iqm):
        np.testing.assert_allclose(metric(stack), [metric(m) for m in stack])
        np.testing.assert_allclose(metric(masked), [metric(m) for m in masked])
    np.testing.assert_allclose(
        metrics.probability_of_improvement(stack, stack[::-1]),
        [metrics.probability_of_improvement(a, b) for a, b in zip(stack, stack[::-1], strict=True)],
    )
    np.testing.assert_allclose(metrics.context_optimality_gap(stack, stack + 3.0), [3.0, 3.0, 3.0])


def test_bootstrap_of_two_runs_spans_both_values():
    # resampled means of [0, 1] are 0 (p=1/4), 0.5 (1/2), 1 (1/4): the 95 % interval is [0, 1]
    interval = intervals.bootstrap_ci([[0.0], [1.0]], metrics.aggregate_mean, reps=4000, seed=3)
    assert interval.point == 0.5
    assert (interval.low, interval.high) == (0.0, 1.0)


def test_bootstrap_of_one_run_collapses_to_the_point():
    interval = intervals.bootstrap_ci([[4.0, 6.0]], metrics.aggregate_mean, reps=100, seed=0)
    assert interval.low == interval.point == interval.high == 5.0


def test_each_design_resamples_its_own_unit():
    """SEEDS: a replicate's rows are whole seeds; RUNS with fixed contexts: each context keeps its
    own runs, mixed across seeds; RUNS with sampled contexts: whole contexts, runs kept together."""
    scores = np.arange(12.0).reshape(3, 4)  # seed i, context j holds 4i + j
    rng = np.random.default_rng(0)
    rows = intervals._resample(scores, intervals.SEEDS, 200, None, rng)
    assert all(any((r == s).all() for s in scores) for m in rows for r in m)
    runs = intervals._resample(scores, intervals.RUNS, 200, None, rng)
    assert (runs % 4 == np.arange(4)).all()
    assert any(not any((r == s).all() for s in scores) for m in runs for r in m)
    columns = rng.integers(0, 4, size=(200, 4))
    nested = intervals._resample(scores, intervals.RUNS, 200, columns, rng)
    np.testing.assert_array_equal(nested, scores[:, columns].transpose(1, 0, 2))
    crossed = intervals._resample(scores, intervals.SEEDS, 200, columns, rng)
    assert (crossed % 4 == columns[:, None, :]).all()


def test_few_seeds_widen_the_interval_as_students_t_does():
    """Hesterberg's expanded percentile: with n seeds the tails move from α/2 to
    Φ(−√(n/(n−1))·t_{n−1}); many seeds leave the plain percentile interval."""
    assert intervals.tail_probability(0.95, 10, 9) == pytest.approx(
        scipy.stats.norm.sf(np.sqrt(10 / 9) * scipy.stats.t.ppf(0.975, 9))
    )
    assert intervals.tail_probability(0.95, 10, 9) < 0.01
    assert intervals.tail_probability(0.95, 10**6, 10**6) == pytest.approx(0.025, abs=1e-4)
    assert intervals.tail_probability(0.95, 1, 0) == pytest.approx(0.025)
    scores = np.random.default_rng(1).normal(size=(10, 1))
    seeds = intervals.bootstrap_ci(scores, metrics.aggregate_mean, reps=4000, seed=0)
    half = scipy.stats.t.ppf(0.975, 9) * scores.std(ddof=1) / np.sqrt(10)
    assert seeds.high - seeds.low == pytest.approx(2 * half, rel=0.15)


def test_same_seed_same_interval_other_seed_other_interval():
    rng = np.random.default_rng(7)
    scores = rng.normal(size=(10, 5))
    a = intervals.bootstrap_ci(scores, metrics.aggregate_iqm, reps=500, seed=11)
    b = intervals.bootstrap_ci(scores, metrics.aggregate_iqm, reps=500, seed=11)
    c = intervals.bootstrap_ci(scores, metrics.aggregate_iqm, reps=500, seed=12)
    assert a == b
    assert (a.low, a.high) != (c.low, c.high)
    assert a.low <= a.point <= a.high
    np.random.seed(0)  # the global RNG plays no part
    assert intervals.bootstrap_ci(scores, metrics.aggregate_iqm, reps=500, seed=11) == a


def test_adding_a_metric_keeps_the_other_intervals():
    scores = {"a": np.arange(12.0).reshape(4, 3)}
    one = intervals.interval_estimates(scores, {"mean": metrics.aggregate_mean}, reps=300, seed=1)
    two = intervals.interval_estimates(
        scores, {"mean": metrics.aggregate_mean, "iqm": metrics.aggregate_iqm}, reps=300, seed=1
    )
    assert one["a"]["mean"] == two["a"]["mean"]


def test_paired_interval_of_improvement():
    better = np.full((5, 4), 2.0)
    worse = np.full((5, 4), 1.0)
    interval = intervals.two_sample_ci(
        better, worse, metrics.probability_of_improvement, reps=200, seed=0
    )
    assert interval.point == interval.low == interval.high == 1.0


def test_curve_band_contains_mean_and_validates():
    curves = np.array([[0.0, 1.0, 2.0], [2.0, 3.0, 4.0]])
    mean, low, high = intervals.curve_band(curves, reps=200, seed=0)
    np.testing.assert_allclose(mean, [1.0, 2.0, 3.0])
    assert np.all(low <= mean) and np.all(mean <= high)
    np.testing.assert_allclose(low, [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="confidence"):
        intervals.bootstrap_ci(curves, metrics.aggregate_mean, confidence=1.5)
    with pytest.raises(ValueError, match="reps"):
        intervals.bootstrap_ci(curves, metrics.aggregate_mean, reps=0)
