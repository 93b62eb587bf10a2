"""Aggregate metrics over a score matrix shaped (runs × contexts), with rliable's definitions.

A *run* is one independently trained agent (a seed); a *context* plays the role of rliable's *task*.
Every function takes a matrix and returns a float; given a stack of matrices (leading axes, the
bootstrap's replicates) it returns one value per matrix, so :mod:`contextrl.analysis.intervals`
evaluates thousands of replicates in one array operation. A missing cell (a run that failed or has
not finished) is marked in a ``numpy.ma.MaskedArray``, never by NaN: every metric is then computed on
the cells that exist (a context with no run left out of the per-context means), so a report never
drops a whole run for one missing context.
"""

from __future__ import annotations

import numpy as np


def as_scores(scores, name: str = "scores") -> np.ndarray:
    """A checked float64 matrix (runs × contexts), or a stack of them (leading axes); refuses empty
    input and NaN/inf. A 1-D input is one context's runs.

    A masked array keeps its mask (the missing cells) when some cell is masked; NaN or inf in a
    present cell is refused either way, so a missing cell is always declared, never inferred."""
    mask = np.ma.getmaskarray(scores) if isinstance(scores, np.ma.MaskedArray) else None
    array = np.asarray(np.ma.getdata(scores), dtype=np.float64)
    if array.ndim == 1:
        array = array[:, None]
        mask = None if mask is None else mask[:, None]
    if array.ndim < 2 or 0 in array.shape:
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


def _value(result):
    """A float for one matrix, an array (NaN where undefined) for a stack of them."""
    if np.ma.isMaskedArray(result):
        result = np.ma.filled(result.astype(np.float64), np.nan)
    result = np.asarray(result, dtype=np.float64)
    return float(result) if result.ndim == 0 else result


def present(scores, name: str = "scores") -> np.ndarray:
    """The scores that exist, flattened (every cell of an unmasked matrix)."""
    return np.ma.compressed(as_scores(scores, name))


def context_means(scores, name: str = "scores") -> np.ndarray:
    """Per context, the mean over its runs; masked where a context has no run."""
    return as_scores(scores, name).mean(axis=-2)


def aggregate_mean(scores) -> float:
    """Mean over contexts of the per-context mean over runs."""
    means = context_means(scores)
    mean = np.ma.mean if np.ma.isMaskedArray(means) else np.mean
    return _value(mean(means, axis=-1))


def aggregate_median(scores) -> float:
    """Median over contexts of the per-context mean over runs (rliable's definition)."""
    means = context_means(scores)
    median = np.ma.median if np.ma.isMaskedArray(means) else np.median
    return _value(median(means, axis=-1))


def _trimmed(flat: np.ndarray) -> float:
    flat = np.sort(flat)
    cut = int(0.25 * flat.size)
    return float(np.mean(flat[cut : flat.size - cut]))


def aggregate_iqm(scores) -> float:
    """Interquartile mean: the mean of the middle 50 % of all run×context scores.

    Same as ``scipy.stats.trim_mean(scores, 0.25, axis=None)``: ``floor(n/4)`` values are cut from each end.
    """
    scores = as_scores(scores)
    lead = scores.shape[:-2]
    flat = scores.reshape(*lead, -1)
    if isinstance(flat, np.ma.MaskedArray):  # cells present differ between matrices
        values = [_trimmed(np.ma.compressed(m)) for m in flat.reshape(-1, flat.shape[-1])]
        return _value(np.reshape(values, lead))
    flat = np.sort(flat, axis=-1)
    cut = int(0.25 * flat.shape[-1])
    return _value(flat[..., cut : flat.shape[-1] - cut].mean(axis=-1))


def aggregate_optimality_gap(scores, threshold: float = 1.0) -> float:
    """rliable's optimality gap: how far scores fall short of ``threshold`` on average (above counts 0)."""
    return float(threshold - np.mean(np.minimum(present(scores), threshold)))


def context_optimality_gap(scores, optimal) -> float:
    """The paper's optimality gap E_c[G*(c) − G(c)]: mean over contexts of optimal minus achieved.

    ``optimal`` holds the optimal (or specialist) return per context: shape (contexts,) or a
    (runs × contexts) matrix whose per-context mean is used. Contexts missing on either side are left
    out of the mean.
    """
    gaps = np.ma.masked_invalid(per_context_gap(scores, optimal))
    if np.ma.count(gaps) == 0:
        raise ValueError("no context has both an achieved and an optimal return")
    return _value(np.ma.mean(gaps, axis=-1))


def per_context_gap(scores, optimal) -> np.ndarray:
    """Optimal minus achieved mean return for each context (shape (contexts,)); NaN where either
    side has no run on the context."""
    achieved = context_means(scores)
    optimal = as_scores(optimal, "optimal") if np.ndim(optimal) > 1 else np.atleast_2d(optimal)
    best = context_means(optimal, "optimal")
    if best.shape[-1] != achieved.shape[-1]:
        raise ValueError(
            f"optimal returns cover {best.shape[-1]} contexts but scores cover {achieved.shape[-1]}"
        )
    return np.ma.filled(np.ma.asarray(best - achieved, dtype=np.float64), np.nan)


def difference_of_means(scores_x, scores_y) -> float:
    """Mean return of X minus mean return of Y (each :func:`aggregate_mean`)."""
    return aggregate_mean(scores_x) - aggregate_mean(scores_y)


def probability_of_improvement(scores_x, scores_y) -> float:
    """P(X > Y): per context, the Mann–Whitney U statistic over run pairs (ties count ½); mean over
    contexts (over the pairs of runs that exist, and the contexts where both X and Y have one)."""
    x, y = as_scores(scores_x, "scores_x"), as_scores(scores_y, "scores_y")
    if x.shape[-1] != y.shape[-1]:
        raise ValueError(f"scores_x has {x.shape[-1]} contexts but scores_y has {y.shape[-1]}")
    left, right = np.ma.getdata(x)[..., :, None, :], np.ma.getdata(y)[..., None, :, :]
    if not (np.ma.isMaskedArray(x) or np.ma.isMaskedArray(y)):  # every pair exists: count them
        wins = np.count_nonzero(left > right, axis=(-3, -2))
        wins = wins + 0.5 * np.count_nonzero(left == right, axis=(-3, -2))
        return _value(np.mean(wins / (x.shape[-2] * y.shape[-2]), axis=-1))
    pairs = ~np.ma.getmaskarray(x)[..., :, None, :] & ~np.ma.getmaskarray(y)[..., None, :, :]
    wins = (((left > right) + 0.5 * (left == right)) * pairs).sum(axis=(-3, -2))
    counts = pairs.sum(axis=(-3, -2))
    if not counts.any():
        raise ValueError("scores_x and scores_y have no context where both have a run")
    per_context = np.ma.MaskedArray(wins / np.maximum(counts, 1), counts == 0)
    return _value(np.ma.mean(per_context, axis=-1))


def fraction_solved(scores, threshold: float) -> float:
    """Fraction of run×context scores at or above ``threshold`` (the paper's "finished episodes")."""
    scores = as_scores(scores)
    return _value(np.ma.mean(scores >= threshold, axis=(-2, -1)))


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
