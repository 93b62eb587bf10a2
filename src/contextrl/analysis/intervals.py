"""Seeded stratified-bootstrap confidence intervals (rliable's method, with an explicit Generator).

Stratified by context: each bootstrap replicate resamples the runs of every context independently,
with replacement, so every context keeps its weight (rliable's ``StratifiedBootstrap``). rliable draws
from NumPy's global RNG; here every draw comes from ``numpy.random.default_rng(seed)``, so the same seed
always gives the same interval.
"""

from __future__ import annotations

import dataclasses
import hashlib
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
    """One replicate: for each context, its runs drawn with replacement.

    A context of a masked matrix draws as many runs as it has, from those it has; the rest of its
    column stays masked, so a context with fewer runs keeps its weight and its spread."""
    runs, contexts = scores.shape
    if not isinstance(scores, np.ma.MaskedArray):
        rows = rng.integers(0, runs, size=(runs, contexts))
        return scores[rows, np.arange(contexts)[None, :]]
    mask = np.ma.getmaskarray(scores)
    counts = (~mask).sum(axis=0)
    present_first = np.argsort(mask, axis=0, kind="stable")  # each column's present runs on top
    draws = rng.integers(0, np.maximum(counts, 1)[None, :], size=(runs, contexts))
    rows = np.take_along_axis(present_first, draws, axis=0)
    values = np.ma.getdata(scores)[rows, np.arange(contexts)[None, :]]
    return np.ma.MaskedArray(values, np.arange(runs)[:, None] >= counts[None, :])


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

    Each (matrix, metric) pair gets its own generator derived from ``seed``, the metric's name and the
    scores themselves (values and missing cells), not from names or positions: the same statistic of
    the same scores has the same interval in every table of a report, and adding a metric or an agent
    never changes the intervals of the others.
    """
    out: dict[str, dict[str, Interval]] = {}
    for name, scores in scores_by_name.items():
        checked = as_scores(scores, str(name))
        fingerprint = hashlib.blake2b(repr(checked.shape).encode(), digest_size=8)
        fingerprint.update(np.ma.getdata(checked).tobytes())
        fingerprint.update(np.ma.getmaskarray(checked).tobytes())
        out[name] = {}
        for metric_name, metric in metrics.items():
            stream = hashlib.blake2b(metric_name.encode(), digest_size=8, key=fingerprint.digest())
            entropy = [seed, *np.frombuffer(stream.digest(), dtype=np.uint32).tolist()]
            sub_seed = int(np.random.SeedSequence(entropy).generate_state(1)[0])
            out[name][metric_name] = bootstrap_ci(
                checked, metric, reps=reps, confidence=confidence, seed=sub_seed
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
    # a point no resampled run reaches has no mean in that replicate (masked cells: missing runs)
    means = np.ma.filled(curves[rows].mean(axis=1), np.nan)
    alpha = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.nanpercentile(means, [alpha, 100.0 - alpha], axis=0)
    return np.ma.filled(curves.mean(axis=0), np.nan), low, high
