"""Aggregate metrics with seeded stratified-bootstrap confidence intervals, plots and HTML reports."""

from contextrl.analysis.intervals import (
    Interval,
    bootstrap_ci,
    interval_estimates,
    paired_bootstrap_ci,
)
from contextrl.analysis.metrics import (
    aggregate_iqm,
    aggregate_mean,
    aggregate_median,
    aggregate_optimality_gap,
    context_optimality_gap,
    fraction_solved,
    per_context_gap,
    probability_of_improvement,
)

__all__ = [
    "Interval",
    "aggregate_iqm",
    "aggregate_mean",
    "aggregate_median",
    "aggregate_optimality_gap",
    "bootstrap_ci",
    "context_optimality_gap",
    "fraction_solved",
    "interval_estimates",
    "paired_bootstrap_ci",
    "per_context_gap",
    "probability_of_improvement",
]
