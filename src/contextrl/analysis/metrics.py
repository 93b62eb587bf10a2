"""Aggregate metrics over a score matrix shaped (runs × contexts), with rliable's definitions.

A *run* is one independently trained agent (a seed); a *context* plays the role of rliable's *task*.
Every function takes a 2-D array and returns a float, so it can be bootstrapped by
:mod:`contextrl.analysis.intervals`. A missing cell (a run that failed or has not finished) is marked
in a ``numpy.ma.MaskedArray``, never by NaN: every metric is then computed on the cells that exist
(a context with no run left out of the per-context means), so a report never drops a whole run for
one missing context.
"""

from __future__ import annotations

import numpy as np


def as_scores(scores, name: str = "scores") -> np.ndarray:
    """A checked float64 matrix (runs × contexts); refuses other shapes, empty input and NaN/inf.

    A masked array keeps its mask (the missing cells) when some cell is masked; NaN or inf in a
    present cell is refused either way, so a missing cell is always declared, never inferred."""
    mask = np.ma.getmaskarray(scores) if isinstance(scores, np.ma.MaskedArray) else None
    array = np.asarray(np.ma.getdata(scores), dtype=np.float64)
    if array.ndim == 1:
        array = array[:, None]
        mask = None if mask is None else mask[:, None]
    if array.ndim != 2 or array.shape[0] < 1 or array.shape[1] < 1:
        raise ValueError(
            f"{name} must be a non-empty (runs × contexts) matrix, got shape {array.shape}"
        )
    present = array if mask is None else array[~mask]
    if present.size == 0:
        raise ValueError(f"{name} has no present cell (every cell is masked as missing)")
    if not np.all(np.isfinite(present)):
        raise ValueError(f"{name} contains NaN or inf")
    if mask is None or not mask.any():
        return array
    return np.ma.MaskedArray(array, mask)


def present(scores, name: str = "scores") -> np.ndarray:
    """The scores that exist, flattened (every cell of an unmasked matrix)."""
    return np.ma.compressed(as_scores(scores, name))


def context_means(scores, name: str = "scores") -> np.ndarray:
    """Per context, the mean over its runs; masked where a context has no run."""
    return as_scores(scores, name).mean(axis=0)


def aggregate_mean(scores) -> float:
    """Mean over contexts of the per-context mean over runs."""
    return float(np.mean(np.ma.compressed(context_means(scores))))


def aggregate_median(scores) -> float:
    """Median over contexts of the per-context mean over runs (rliable's definition)."""
    return float(np.median(np.ma.compressed(context_means(scores))))


def aggregate_iqm(scores) -> float:
    """Interquartile mean: the mean of the middle 50 % of all run×context scores.

    Same as ``scipy.stats.trim_mean(scores, 0.25, axis=None)``: ``floor(n/4)`` values are cut from each end.
    """
    flat = np.sort(present(scores))
    cut = int(0.25 * flat.size)
    return float(np.mean(flat[cut : flat.size - cut]))


def aggregate_optimality_gap(scores, threshold: float = 1.0) -> float:
    """rliable's optimality gap: how far scores fall short of ``threshold`` on average (above counts 0)."""
    return float(threshold - np.mean(np.minimum(present(scores), threshold)))


def context_optimality_gap(scores, optimal) -> float:
    """The paper's optimality gap E_c[G*(c) − G(c)]: mean over contexts of optimal minus achieved.

    ``optimal`` holds the optimal (or specialist) return per context: shape (contexts,) or a
    (runs × contexts) matrix whose per-context mean is used. Contexts missing on either side are left
    out of the mean.
    """
    gaps = np.ma.compressed(np.ma.masked_invalid(per_context_gap(scores, optimal)))
    if gaps.size == 0:
        raise ValueError("no context has both an achieved and an optimal return")
    return float(np.mean(gaps))


def per_context_gap(scores, optimal) -> np.ndarray:
    """Optimal minus achieved mean return for each context (shape (contexts,)); NaN where either
    side has no run on the context."""
    achieved = context_means(scores)
    best = context_means(np.atleast_2d(optimal), "optimal")
    if best.shape != achieved.shape:
        raise ValueError(
            f"optimal returns cover {best.shape[0]} contexts but scores cover {achieved.shape[0]}"
        )
    return np.ma.filled(np.ma.asarray(best - achieved, dtype=np.float64), np.nan)


def probability_of_improvement(scores_x, scores_y) -> float:
    """P(X > Y): per context, the Mann–Whitney U statistic over run pairs (ties count ½); mean over
    contexts (over the pairs of runs that exist, and the contexts where both X and Y have one)."""
    x, y = as_scores(scores_x, "scores_x"), as_scores(scores_y, "scores_y")
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"scores_x has {x.shape[1]} contexts but scores_y has {y.shape[1]}")
    pairs = ~np.ma.getmaskarray(x)[:, None, :] & ~np.ma.getmaskarray(y)[None, :, :]
    left, right = np.ma.getdata(x)[:, None, :], np.ma.getdata(y)[None, :, :]
    wins = ((left > right) + 0.5 * (left == right)) * pairs
    counts = pairs.sum(axis=(0, 1))
    if not counts.any():
        raise ValueError("scores_x and scores_y have no context where both have a run")
    return float(np.mean(wins.sum(axis=(0, 1))[counts > 0] / counts[counts > 0]))


def fraction_solved(scores, threshold: float) -> float:
    """Fraction of run×context scores at or above ``threshold`` (the paper's "finished episodes")."""
    return float(np.mean(present(scores) >= threshold))


def near_best_threshold(*score_sets, tolerance: float = 0.01) -> float:
    """The return at which a score counts as "at the best": within ``tolerance`` of the observed
    range (best − worst) below the best score. Unlike a multiple of the best, it works for negative
    returns (0.99 × a negative best lies above every score)."""
    values = np.concatenate([present(s) for s in score_sets])
    best, worst = values.max(), values.min()
    return float(best - tolerance * (best - worst))


METRICS = {
    "mean": aggregate_mean,
    "median": aggregate_median,
    "iqm": aggregate_iqm,
}
