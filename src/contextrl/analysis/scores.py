"""The statistics every report number is computed from, as pure functions of the results table:
score cells (one row per agent kind, variant, test set, context and seed), score matrices with the
unit their intervals resample, intervals per agent, the optimality gap, the sensitivity lines and the
learned-or-not rule. Reports, protocols and the paper's checks all call these, so one number is
computed one way wherever it appears."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from contextrl.analysis import metrics
from contextrl.analysis.intervals import (
    RUNS,
    SAMPLED,
    SEEDS,
    Interval,
    interval_estimates,
    two_sample_ci,
)

CI_METRICS = {
    "mean": metrics.aggregate_mean,
    "median": metrics.aggregate_median,
    "IQM": metrics.aggregate_iqm,
}


# Trained agents "clearly beat" the random policy on their training contexts when their mean return
# is above the random policy's by at least this fraction of the larger of |random return| and 1.
LEARNED_MARGIN = 0.1


CELL = ("kind", "variant", "test_set", "context", "seed")  # the key of a score cell


def natural_key(text: Any) -> tuple:
    """Sort key that orders embedded numbers by value: random-2 before random-10."""
    return tuple(
        (0, int(part), "") if part.isdigit() else (1, 0, part)
        for part in re.split(r"(\d+)", str(text))
        if part
    )


def agent_label(frame: pd.DataFrame) -> pd.Series:
    """The variant, prefixed by the trial kind when a run has several kinds (general/specialist…)."""
    if frame["kind"].nunique() > 1:
        return frame["kind"].astype(str) + ", " + frame["variant"].astype(str)
    return frame["variant"].astype(str)


def score_cells(rows: pd.DataFrame) -> pd.DataFrame:
    """The one aggregation every number of a report is read from: a row per (agent kind, variant,
    test set, context, seed) cell, so two sections can never key the same returns differently.

    ``context`` is the ``context`` label where the protocol writes one (the optimality gap: a
    specialist's one-context test set is context i of the training contexts), else the index in
    the test set. ``return`` is the mean over the cell's rows (several only where agents of one kind
    share the contexts: the specialists in ``contextrl eval``; ``trials`` counts them); NaN where no
    row has a finite return, ``missing`` then saying why (the rows of :func:`absent_rows`, or the
    non-finite return). Every other column keeps its first value (features, labels, the trial).
    """
    context = rows["context"] if "context" in rows else rows["context_index"]
    values = rows["return"].to_numpy(float)
    finite = np.isfinite(values)
    known = rows["missing"].fillna("") if "missing" in rows else [""] * len(rows)
    why = [
        w or ("" if ok else f"its return is {v}")
        for w, v, ok in zip(known, values, finite, strict=True)
    ]
    rows = rows.assign(context=context, missing=why, **{"return": np.where(finite, values, np.nan)})
    grouped = rows.groupby(list(CELL), sort=False, dropna=False)
    cells = grouped.first()
    cells["return"] = grouped["return"].mean()
    cells["trials"] = grouped["trial"].nunique()
    cells["missing"] = grouped["missing"].agg(
        lambda reasons: "; ".join(dict.fromkeys(r for r in reasons if r))
    )
    return cells.reset_index()


@dataclasses.dataclass(frozen=True)
class Scores:
    """One agent's score matrix, seeds × (test set, context) columns, masked where a cell is missing,
    with each missing cell as (seed, test set, context, why), and the unit its intervals resample:
    ``SEEDS`` where one agent per seed was tested on every context, ``RUNS`` where every cell is an
    agent of its own (the specialists of the optimality gap)."""

    matrix: np.ndarray
    contexts: tuple[tuple[str, Any], ...]
    missing: tuple[tuple[Any, str, Any, str], ...]
    unit: str = SEEDS

    @property
    def present(self) -> int:
        """How many cells have a return: what every statistic of the agent is computed on."""
        return int(self.matrix.size - np.ma.count_masked(self.matrix))

    @property
    def values(self) -> np.ndarray:
        """The returns that exist, flattened."""
        return np.ma.compressed(self.matrix)

    def cells_note(self) -> str:
        """The cells a statistic is computed on, said in the report next to it."""
        seeds, contexts = self.matrix.shape
        shape = f"{seeds} seeds × {contexts} contexts"
        if self.present == self.matrix.size:
            return f"all {self.matrix.size} ({shape})"
        return f"{self.present} of {self.matrix.size} ({shape}; the missing under Missing results)"


def score_matrices(cells: pd.DataFrame, labels: pd.Series | None = None) -> dict[str, Scores]:
    """Per label (default: :func:`agent_label`), naturally sorted, the :class:`Scores` of its cells
    (from :func:`score_cells`); a label whose rows share a cell (two kinds or variants under one
    label) is refused rather than averaged."""
    labels = agent_label(cells) if labels is None else labels
    out = {}
    for name, group in sorted(cells.groupby(labels, sort=False), key=lambda g: natural_key(g[0])):
        indexed = group.set_index(["seed", "test_set", "context"])
        if indexed.index.has_duplicates:
            raise ValueError(
                f"score matrix {name!r}: several agents share a (seed, test set, context) cell; "
                "label each kind and variant apart"
            )
        wide = indexed["return"].unstack(["test_set", "context"])
        columns = sorted(wide.columns, key=lambda c: (natural_key(c[0]), natural_key(c[1])))
        wide = wide[columns].sort_index()
        matrix = np.ma.masked_invalid(wide.to_numpy(float))
        why = indexed["missing"]
        missing = tuple(
            (
                seed,
                test_set,
                context,
                why.get((seed, test_set, context)) or "no result, no record why",
            )
            for seed, row in zip(wide.index, np.ma.getmaskarray(matrix), strict=True)
            for (test_set, context), absent in zip(columns, row, strict=True)
            if absent
        )
        out[name] = Scores(
            matrix if missing else matrix.data, tuple(columns), missing, _unit(group)
        )
    return out


def _unit(cells: pd.DataFrame) -> str:
    """``RUNS`` when every cell is one agent that no other cell shares (each specialist tested on
    its own context), else ``SEEDS`` (a seed's agent, or agents, tested on several contexts)."""
    own = (cells["trials"] == 1).all() and not cells["trial"].duplicated().any()
    return RUNS if own and cells["context"].nunique() > 1 else SEEDS


def design_words(scores: Mapping[str, Scores], contexts: str) -> str:
    """What the intervals of ``scores`` resample, in the words a report prints beside them."""
    units = {s.unit for s in scores.values()}
    seeds = "seeds (each with all its contexts)" if SEEDS in units else ""
    if contexts == SAMPLED:
        drawn = "the test contexts" + (", each with its runs" if RUNS in units else "")
        return f"{seeds} and {drawn}" if seeds else drawn
    runs = "each context's runs" if RUNS in units else ""
    return " and ".join(part for part in (seeds, runs) if part)


def score_intervals(
    scores: Mapping[str, Scores],
    *,
    contexts: str,
    reps: int,
    seed: int,
    metrics_: Mapping[str, Callable] = CI_METRICS,
) -> tuple[dict[str, dict[str, Interval]], list[dict]]:
    """Bootstrap intervals of every agent with a present cell, each resampling its own unit (and
    the test contexts where ``contexts`` is ``SAMPLED``), and a table row per agent saying which cells
    its statistics are computed on (an agent with none says so instead)."""
    shown_scores = {name: s for name, s in scores.items() if s.present}
    intervals = interval_estimates(
        {name: s.matrix for name, s in shown_scores.items()},
        metrics_,
        units={name: s.unit for name, s in shown_scores.items()},
        contexts=contexts,
        reps=reps,
        seed=seed,
    )

    def shown(name: str, metric: str) -> str:
        if name not in intervals:
            return "no result"
        return stated(intervals[name][metric], {name: scores[name]})

    rows = [
        {
            "agent": name,
            **{metric: shown(name, metric) for metric in metrics_},
            "cells (seeds × contexts)": s.cells_note(),
        }
        for name, s in scores.items()
    ]
    return intervals, rows


ONE_SEED = "no interval with one seed"


def has_interval(scores: Mapping[str, Scores]) -> bool:
    """Whether a statistic of ``scores`` gets an interval: some agent has several seeds. A bootstrap
    over one seed says nothing of another seed's training, which a "95% CI" would present as known."""
    return any(s.matrix.shape[0] > 1 for s in scores.values())


def stated(interval: Interval, scores: Mapping[str, Scores]) -> str:
    """A statistic of ``scores`` as every table and text prints it: ``point [low, high]``, or the
    point and ``(no interval with one seed)``."""
    return str(interval) if has_interval(scores) else f"{interval.point:.4g} ({ONE_SEED})"


def interval_words(scores: Mapping[str, Scores], contexts: str) -> str:
    """``95% CI over …`` naming what was resampled, or ``no interval with one seed``."""
    return f"95% CI over {design_words(scores, contexts)}" if has_interval(scores) else ONE_SEED


def interval_title(title: str, scores: Mapping[str, Scores], contexts: str) -> str:
    """``title (95% CI over …)`` or ``title (no interval with one seed)``."""
    return f"{title} ({interval_words(scores, contexts)})"


def drawn_intervals(
    intervals: Mapping[str, Mapping[str, Interval]], scores: Mapping[str, Scores]
) -> dict[str, dict[str, Interval]]:
    """The intervals a figure draws: an agent with one seed as its point alone, with no bar."""
    return {
        name: dict(by_metric)
        if has_interval({name: scores[name]})
        else {metric: Interval(i.point, i.point, i.point) for metric, i in by_metric.items()}
        for name, by_metric in intervals.items()
    }


def missing_rows(scores: Mapping[str, Scores]) -> list[dict]:
    """One row per agent, seed, test set and reason: the contexts that have no result."""
    grouped: dict[tuple, list] = {}
    for name, s in scores.items():
        for seed, test_set, context, why in s.missing:
            grouped.setdefault((name, seed, test_set, why), []).append(context)
    return [
        {
            "agent": name,
            "seed": seed,
            "test set": test_set,
            "contexts": ", ".join(str(c) for c in contexts),
            "why": why,
        }
        for (name, seed, test_set, why), contexts in grouped.items()
    ]


def _binned(x: np.ndarray, bins: int = 12) -> np.ndarray:
    """Each value's bin centre: the values themselves when there are few, else equal-width bins."""
    unique = np.unique(x)
    if unique.size <= 2 * bins:
        return x
    edges = np.linspace(unique[0], unique[-1], bins + 1)
    index = np.clip(np.digitize(x, edges) - 1, 0, bins - 1)
    return ((edges[:-1] + edges[1:]) / 2)[index]


def return_lines(
    results: pd.DataFrame, column: str, labels: pd.Series | None = None
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per label (default: the agent label): x (the value of ``column``, binned when there are many)
    and the mean return of each seed there, shaped seeds × points (masked where a seed has none)."""
    labels = agent_label(results) if labels is None else labels
    frame = results.assign(agent=labels, x=_binned(results[column].to_numpy(float)))
    lines = {}
    for label in sorted(frame["agent"].unique(), key=natural_key):
        group = frame[frame["agent"] == label]
        wide = group.pivot_table(index="seed", columns="x", values="return", aggfunc="mean")
        if wide.shape[1]:  # a seed without a return at a point is masked there, not dropped
            runs = np.ma.masked_invalid(wide.to_numpy(float))
            lines[label] = (wide.columns.to_numpy(float), runs if runs.mask.any() else runs.data)
    return lines


def learned(trained: float, random: float) -> bool:
    """Whether a mean trained return clearly beats the random policy's (see LEARNED_MARGIN)."""
    return trained - random >= LEARNED_MARGIN * max(abs(random), 1.0)


@dataclasses.dataclass(frozen=True)
class GapStatistics:
    """One variant's optimality gap as the report and the paper's check state it.

    Every interval resamples the general agent's seeds (each with all its contexts) and the
    contexts, each with its specialists: the contexts are a sample from the distribution the gap is
    defined over."""

    general: Scores
    specialists: Scores
    gap: Interval  # E_c[G_specialist(c) − G_general(c)]
    differences: dict  # specialists' minus the general agent's mean, median and IQM
    improvement: Interval  # P(a specialist beats the general agent on a context)
    finished: dict  # the fraction of cells at the best return: general, specialists, difference
    aggregates: list  # mean, median, IQM with their intervals, one row per agent
    intervals: dict  # the same intervals for the figure

    def per_seed(self) -> dict[str, np.ndarray]:
        """Each seed's mean return over its contexts: shows a gap carried by a few failed seeds."""
        return {
            "general": np.ma.filled(np.ma.mean(self.general.matrix, axis=1), np.nan),
            "specialists": np.ma.filled(np.ma.mean(self.specialists.matrix, axis=1), np.nan),
        }


def _aggregate_difference(aggregate):
    """Specialists' (second argument) aggregate minus the general agent's (first)."""
    return lambda general, specialists: aggregate(specialists) - aggregate(general)


def gap_statistics(
    cells: pd.DataFrame, variants: Sequence[str], *, contexts: str, reps: int, seed: int
) -> dict[str, GapStatistics]:
    """Per variant with both kinds (``general``, ``specialist``) finished, the gap, the differences
    of the aggregates, the probability of improvement and the finished fractions, with intervals
    of ``reps`` bootstrap replicates from ``seed`` (``contexts``: the test contexts' design)."""
    out = {}
    for variant in variants:
        mine = cells[cells["variant"] == variant]
        scores = score_matrices(mine, mine["kind"])
        g, s = scores.get("general"), scores.get("specialist")
        if g is None or s is None or not (g.present and s.present):
            continue
        if [c for _, c in g.contexts] != [c for _, c in s.contexts]:
            raise ValueError(
                f"optimality gap ({variant}): the general agent was tested on contexts "
                f"{[c for _, c in g.contexts]} but the specialists on {[c for _, c in s.contexts]}"
            )
        out[variant] = _gap(g, s, {"contexts": contexts, "reps": reps, "seed": seed})
    return out


def _gap(g: Scores, s: Scores, design: dict) -> GapStatistics:
    cis, rows = score_intervals({"general": g, "specialists": s}, **design)

    def interval(metric, first=g, second=s):
        return two_sample_ci(
            first.matrix, second.matrix, metric, units=(first.unit, second.unit), **design
        )

    threshold = metrics.near_best_threshold(g.matrix, s.matrix)
    return GapStatistics(
        g,
        s,
        interval(metrics.context_optimality_gap),
        {
            name: interval(_aggregate_difference(aggregate))
            for name, aggregate in CI_METRICS.items()
        },
        interval(metrics.probability_of_improvement, s, g),
        {
            "threshold": threshold,
            "general": metrics.fraction_solved(g.matrix, threshold),
            "specialists": metrics.fraction_solved(s.matrix, threshold),
            "difference": interval(
                _aggregate_difference(lambda m: metrics.fraction_solved(m, threshold))
            ),
        },
        rows,
        cis,
    )


DEFAULT_LABEL = "(default)"  # the feature label of the shared default-context evaluation


def magnitude_lines(
    cells: pd.DataFrame, label: str = "variant"
) -> dict[str, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """Per feature: {label: (magnitudes, returns shaped seeds × magnitudes)}, from the score cells
    (``label`` names the column that tells the lines apart); the one default evaluation is every
    feature's A = 1 point."""
    default = cells[cells["feature"] == DEFAULT_LABEL]
    out = {}
    for feature in [f for f in cells["feature"].unique() if f != DEFAULT_LABEL]:
        rows = pd.concat([cells[cells["feature"] == feature], default])
        out[feature] = return_lines(rows, "magnitude", rows[label])
    return out


def worst_drop(runs: np.ndarray, default_column: int) -> np.ndarray:
    """How far the worst magnitude's mean return falls below the default's (``runs``: seeds ×
    magnitudes, with any leading axes of bootstrap samples)."""
    means = np.ma.filled(np.ma.mean(runs, axis=-2), np.nan)
    return means[..., default_column] - np.nanmin(means, axis=-1)


def per_seed_means(cells: pd.DataFrame) -> pd.Series:
    """Each seed's mean return over ``cells`` (all its agents' cells there)."""
    return cells.groupby("seed")["return"].mean()
