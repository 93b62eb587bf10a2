"""The optimality-gap protocol (paper §6.2): one general agent trained on N sampled contexts against one
specialist per context, each evaluated on the context(s) it was trained on."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from contextrl.analysis import metrics, plots
from contextrl.analysis.intervals import paired_bootstrap_ci
from contextrl.analysis.report import Section
from contextrl.experiments.analyze import (
    figure,
    interval_title,
    score_intervals,
    score_matrices,
    training_figure,
)
from contextrl.experiments.protocols import TRAIN_KEY, ContextSet, Plan, Trial, draw_set, grid
from contextrl.experiments.spec import CommonSpec, _check_int, register_protocol


@register_protocol
@dataclasses.dataclass(frozen=True)
class OptimalityGapSpec(CommonSpec):
    """One general agent on N sampled contexts vs one specialist per context (paper §6.2)."""

    protocol: str = "optimality_gap"

    train: dict | None = None  # None: the environment's default (spec.ENV_DEFAULTS)
    env_defaults = ("train",)
    num_contexts: int = 64

    def validate(self) -> None:
        super().validate()
        _check_int("num_contexts", self.num_contexts, 1)
        self.resolve_features("train", self.train)

    def expand(self) -> tuple[dict, list]:
        return _expand(self)

    def sections(self, plan, results, curves) -> list[Section]:
        training = (
            [] if curves.empty else [Section("Training", figures=[training_figure(self, curves)])]
        )
        return _sections(self, plan, results) + training


def _expand(spec: OptimalityGapSpec) -> tuple[dict, list]:
    train = draw_set(spec, "train", spec.train, spec.num_contexts, TRAIN_KEY)
    ids = list(range(spec.num_contexts))
    sets = {"train": ContextSet("train", train, {"context": ids})}
    trials = grid(spec, "general", "train", "train")
    for i in ids:
        name = f"train[{i}]"
        sets[name] = ContextSet(name, train[i : i + 1], {"context": [i]})
        trials += [
            Trial(
                f"specialist{i}-{variant}-s{seed}", "specialist", variant, seed, name, name, "train"
            )
            for variant in spec.variants
            for seed in range(spec.seeds)
        ]
    return sets, trials


def _sections(spec: OptimalityGapSpec, plan: Plan, cells: pd.DataFrame) -> list[Section]:
    sections = []
    for variant in spec.variants:
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
        g_scores, s_scores = g.matrix, s.matrix
        cis, rows = score_intervals(
            {"general": g, "specialists": s}, reps=spec.bootstrap_reps, seed=spec.seed
        )
        gap = paired_bootstrap_ci(
            g_scores,
            s_scores,
            metrics.context_optimality_gap,
            reps=spec.bootstrap_reps,
            seed=spec.seed,
        )
        improvement = paired_bootstrap_ci(
            s_scores,
            g_scores,
            metrics.probability_of_improvement,
            reps=spec.bootstrap_reps,
            seed=spec.seed,
        )
        best = float(max(g.values.max(), s.values.max()))
        threshold = metrics.near_best_threshold(g_scores, s_scores)
        solved = {
            "general": metrics.fraction_solved(g_scores, threshold),
            "specialists": metrics.fraction_solved(s_scores, threshold),
        }
        per_context = metrics.per_context_gap(g_scores, s_scores)
        varying = plan.spec.space().varying(plan.sets["train"].contexts)
        feature = varying[0] if varying else None
        for row in rows:
            row["fraction at best return"] = solved[row["agent"]]
        text = [
            f"Variant {variant}: one general agent trained on {spec.num_contexts} contexts vs one "
            f"specialist per context; each evaluated on the context(s) it was trained on "
            f"({spec.eval_episodes} episodes, {spec.seeds} seeds). 95% stratified-bootstrap CIs "
            f"({spec.bootstrap_reps} replicates, seed {spec.seed}).",
            f"Optimality gap E_c[G_specialist(c) − G_general(c)] = {gap}.",
            f"Probability that a specialist beats the general agent on a context: {improvement}.",
            f"Fraction of run×context returns at the best return observed in the run ({best:g}; "
            f"within 1% of the observed return range, i.e. ≥ {threshold:g}): "
            f"general {solved['general']:.2f}, specialists {solved['specialists']:.2f}.",
        ]
        if g.missing or s.missing:
            text.append(
                f"Computed on the cells that exist: general {g.cells_note()}, specialists "
                f"{s.cells_note()}; the gap and the probability use the contexts both have."
            )
        figures = [
            figure(
                f"optgap-ecdf-{variant}",
                plots.ecdf({"general": g.values, "specialists": s.values}, title="Return eCDF"),
                "eCDF of returns of the general agent and the specialists",
            ),
            figure(
                f"optgap-intervals-{variant}",
                plots.intervals(cis, title=interval_title("Aggregate return", scores)),
                "Mean, median and IQM with stratified-bootstrap CIs",
            ),
        ]
        if feature is not None:
            tested = np.asarray([c for _, c in g.contexts], dtype=int)
            values = np.asarray(getattr(plan.sets["train"].contexts, feature))[tested]
            figures.append(
                figure(
                    f"optgap-per-context-{variant}",
                    plots.scatter(
                        values,
                        {"specialist − general": per_context},
                        xlabel=feature,
                        ylabel="return gap",
                        title="Gap per context",
                    ),
                    f"Per-context optimality gap against {feature}",
                )
            )
        sections.append(
            Section(f"Optimality gap ({variant})", text, [("Aggregates", rows)], figures)
        )
    if not sections:
        sections.append(Section("Optimality gap", ["Not enough finished trials for the gap."]))
    return sections
