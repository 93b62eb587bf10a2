"""Aggregate metrics over a score matrix shaped (runs × contexts), with rliable's definitions.

A *run* is one independently trained agent (a seed); a *context* plays the role of rliable's *task*.
Every function takes a 2-D array and returns a float, so it can be bootstrapped by
:mod:`contextrl.analysis.intervals`.
"""

from __future__ import annotations

import numpy as np


def as_scores(scores, name: str = "scores") -> np.ndarray:
    """A checked float64 matrix (runs × contexts); refuses other shapes, empty input and NaN/inf."""
    array = np.asarray(scores, dtype=np.float64)
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim != 2 or array.shape[0] < 1 or array.shape[1] < 1:
        raise ValueError(
            f"{name} must be a non-empty (runs × contexts) matrix, got shape {array.shape}"
        )
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} contains NaN or inf")
    return array


def aggregate_mean(scores) -> float:
    """Mean over contexts of the per-context mean over runs."""
    return float(np.mean(np.mean(as_scores(scores), axis=0)))


def aggregate_median(scores) -> float:
    """Median over contexts of the per-context mean over runs (rliable's definition)."""
    return float(np.median(np.mean(as_scores(scores), axis=0)))


def aggregate_iqm(scores) -> float:
    """Interquartile mean: the mean of the middle 50 % of all run×context scores.

    Same as ``scipy.stats.trim_mean(scores, 0.25, axis=None)``: ``floor(n/4)`` values are cut from each end.
    """
    flat = np.sort(as_scores(scores).ravel())
    cut = int(0.25 * flat.size)
    return float(np.mean(flat[cut : flat.size - cut]))


def aggregate_optimality_gap(scores, threshold: float = 1.0) -> float:
    """rliable's optimality gap: how far scores fall short of ``threshold`` on average (above counts 0)."""
    return float(threshold - np.mean(np.minimum(as_scores(scores), threshold)))


def context_optimality_gap(scores, optimal) -> float:
    """The paper's optimality gap E_c[G*(c) − G(c)]: mean over contexts of optimal minus achieved.

    ``optimal`` holds the optimal (or specialist) return per context: shape (contexts,) or a
    (runs × contexts) matrix whose per-context mean is used.
    """
    achieved = np.mean(as_scores(scores), axis=0)
    best = np.mean(as_scores(np.atleast_2d(optimal), "optimal"), axis=0)
    if best.shape != achieved.shape:
        raise ValueError(
            f"optimal returns cover {best.shape[0]} contexts but scores cover {achieved.shape[0]}"
        )
    return float(np.mean(best - achieved))


def per_context_gap(scores, optimal) -> np.ndarray:
    """Optimal minus achieved mean return for each context (shape (contexts,))."""
    achieved = np.mean(as_scores(scores), axis=0)
    best = np.mean(as_scores(np.atleast_2d(optimal), "optimal"), axis=0)
    if best.shape != achieved.shape:
        raise ValueError(
            f"optimal returns cover {best.shape[0]} contexts but scores cover {achieved.shape[0]}"
        )
    return best - achieved


def probability_of_improvement(scores_x, scores_y) -> float:
    """P(X > Y): per context, the Mann–Whitney U statistic over run pairs (ties count ½); mean over contexts."""
    x, y = as_scores(scores_x, "scores_x"), as_scores(scores_y, "scores_y")
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"scores_x has {x.shape[1]} contexts but scores_y has {y.shape[1]}")
    greater = (x[:, None, :] > y[None, :, :]).mean(axis=(0, 1))
    ties = (x[:, None, :] == y[None, :, :]).mean(axis=(0, 1))
    return float(np.mean(greater + 0.5 * ties))


def fraction_solved(scores, threshold: float) -> float:
    """Fraction of run×context scores at or above ``threshold`` (the paper's "finished episodes")."""
    return float(np.mean(as_scores(scores) >= threshold))


def near_best_threshold(*score_sets, tolerance: float = 0.01) -> float:
    """The return at which a score counts as "at the best": within ``tolerance`` of the observed
    range (best − worst) below the best score. Unlike a multiple of the best, it works for negative
    returns (0.99 × a negative best lies above every score)."""
    values = np.concatenate([as_scores(s).ravel() for s in score_sets])
    best, worst = values.max(), values.min()
    return float(best - tolerance * (best - worst))


METRICS = {
    "mean": aggregate_mean,
    "median": aggregate_median,
    "iqm": aggregate_iqm,
}
