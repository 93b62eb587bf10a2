"""Seeded stratified-bootstrap confidence intervals (rliable's method, with an explicit Generator).

Stratified by context: each bootstrap replicate resamples the runs of every context independently,
with replacement, so every context keeps its weight (rliable's ``StratifiedBootstrap``). rliable draws
from NumPy's global RNG; here every draw comes from ``numpy.random.default_rng(seed)``, so the same seed
always gives the same interval.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping

import numpy as np

from contextrl.analysis.metrics import as_scores


@dataclasses.dataclass(frozen=True)
class Interval:
    """A point estimate and its percentile confidence interval."""

    point: float
    low: float
    high: float

    def as_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)

    def __str__(self) -> str:
        return f"{self.point:.4g} [{self.low:.4g}, {self.high:.4g}]"


def _check(reps: int, confidence: float) -> None:
    if isinstance(reps, bool) or not isinstance(reps, (int, np.integer)) or reps < 1:
        raise ValueError(f"reps must be a positive integer, got {reps!r}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")


def stratified_resample(scores: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One replicate: for each context, the runs drawn with replacement."""
    runs, contexts = scores.shape
    rows = rng.integers(0, runs, size=(runs, contexts))
    return scores[rows, np.arange(contexts)[None, :]]


def _percentiles(point: float, samples: np.ndarray, confidence: float) -> Interval:
    alpha = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(samples, [alpha, 100.0 - alpha])
    return Interval(float(point), float(low), float(high))


def bootstrap_ci(
    scores,
    metric: Callable[[np.ndarray], float],
    *,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> Interval:
    """``metric`` on ``scores`` (runs × contexts) with a stratified-bootstrap percentile interval."""
    _check(reps, confidence)
    scores = as_scores(scores)
    rng = np.random.default_rng(seed)
    samples = np.array([metric(stratified_resample(scores, rng)) for _ in range(reps)])
    return _percentiles(metric(scores), samples, confidence)


def paired_bootstrap_ci(
    scores_x,
    scores_y,
    metric: Callable[[np.ndarray, np.ndarray], float],
    *,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> Interval:
    """A two-sample metric (probability of improvement, gap) with both samples resampled independently."""
    _check(reps, confidence)
    x, y = as_scores(scores_x, "scores_x"), as_scores(scores_y, "scores_y")
    rng = np.random.default_rng(seed)
    samples = np.array(
        [metric(stratified_resample(x, rng), stratified_resample(y, rng)) for _ in range(reps)]
    )
    return _percentiles(metric(x, y), samples, confidence)


def interval_estimates(
    scores_by_name: Mapping[str, np.ndarray],
    metrics: Mapping[str, Callable[[np.ndarray], float]],
    *,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> dict[str, dict[str, Interval]]:
    """Every metric for every named score matrix: ``{name: {metric: Interval}}``.

    Each (name, metric) pair gets its own generator derived from ``seed`` and its position, so adding a
    metric never changes the intervals of the others.
    """
    out: dict[str, dict[str, Interval]] = {}
    for i, (name, scores) in enumerate(scores_by_name.items()):
        out[name] = {}
        for j, (metric_name, metric) in enumerate(metrics.items()):
            sub_seed = int(np.random.SeedSequence([seed, i, j]).generate_state(1)[0])
            out[name][metric_name] = bootstrap_ci(
                scores, metric, reps=reps, confidence=confidence, seed=sub_seed
            )
    return out


def curve_band(
    curves, *, reps: int = 1000, confidence: float = 0.95, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and bootstrap CI of training curves shaped (runs × points), resampling runs."""
    curves = as_scores(curves, "curves")
    _check(reps, confidence)
    rng = np.random.default_rng(seed)
    runs = curves.shape[0]
    rows = rng.integers(0, runs, size=(reps, runs))
    means = curves[rows].mean(axis=1)
    alpha = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(means, [alpha, 100.0 - alpha], axis=0)
    return curves.mean(axis=0), low, high
