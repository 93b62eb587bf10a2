"""Aggregate metrics with seeded, design-aware bootstrap confidence intervals, plots and HTML reports."""

from contextrl.analysis.intervals import (
    FIXED,
    RUNS,
    SAMPLED,
    SEEDS,
    Interval,
    bootstrap_ci,
    interval_estimates,
    two_sample_ci,
)
from contextrl.analysis.metrics import (
    aggregate_iqm,
    aggregate_mean,
    aggregate_median,
    aggregate_optimality_gap,
    context_optimality_gap,
    difference_of_means,
    fraction_solved,
    per_context_gap,
    probability_of_improvement,
)

__all__ = [
    "FIXED",
    "RUNS",
    "SAMPLED",
    "SEEDS",
    "Interval",
    "aggregate_iqm",
    "aggregate_mean",
    "aggregate_median",
    "aggregate_optimality_gap",
    "bootstrap_ci",
    "context_optimality_gap",
    "difference_of_means",
    "fraction_solved",
    "interval_estimates",
    "per_context_gap",
    "probability_of_improvement",
    "two_sample_ci",
]
