"""The optimality-gap protocol (paper §6.2): one general agent trained on N sampled contexts against one
specialist per context, each evaluated on the context(s) it was trained on."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from contextrl.analysis import metrics, plots
from contextrl.analysis.report import Section
from contextrl.analysis.scores import (
    ONE_SEED,
    GapStatistics,
    design_words,
    drawn_intervals,
    gap_statistics,
    has_interval,
    interval_title,
    interval_words,
    stated,
)
from contextrl.experiments.plan import TRAIN_KEY, ContextSet, Plan, Trial, draw_set, grid
from contextrl.experiments.protocol import Protocol, register_protocol
from contextrl.experiments.reports import figure
from contextrl.experiments.spec import (
    MAX_COUNT,
    CommonSpec,
    SpecError,
    check_int,
)


@dataclasses.dataclass(frozen=True)
class OptimalityGapSpec(CommonSpec):
    """One general agent on N sampled contexts vs one specialist per context (paper §6.2)."""

    protocol: str = "optimality_gap"

    train: dict | None = None  # None: the environment's default (spec.ENV_DEFAULTS)
    env_defaults = ("train",)
    num_contexts: int = 64

    def validate(self) -> None:
        super().validate()
        check_int("num_contexts", self.num_contexts, 1)
        agents = self.seeds * len(self.variants) * (self.num_contexts + 1)
        if agents > MAX_COUNT:
            raise SpecError(
                f"num_contexts: {self.num_contexts:,} specialists and a general agent per seed "
                f"and variant make {agents:,} agents to train; at most {MAX_COUNT:,}"
            )
        self.resolve_features("train", self.train)


def _expand(spec: OptimalityGapSpec) -> tuple[dict, list]:
    """The training contexts, each also a set of its own for its specialists, and the trials."""
    train = draw_set(spec, "train", spec.train, spec.num_contexts, TRAIN_KEY)
    ids = list(range(spec.num_contexts))
    sets = {"train": ContextSet("train", train, {"context": ids})}
    for i in ids:
        sets[_own_set(i)] = ContextSet(_own_set(i), train[i : i + 1], {"context": [i]})
    return sets, _trials(spec)


def _outline(spec: OptimalityGapSpec) -> tuple[dict, list]:
    own = {_own_set(i): 1 for i in range(spec.num_contexts)}
    return {"train": spec.num_contexts, **own}, _trials(spec)


def _own_set(i: int) -> str:
    """The set of training context ``i`` alone: its specialists train and are tested there."""
    return f"train[{i}]"


def _trials(spec: OptimalityGapSpec) -> list[Trial]:
    """The general agents (trained and tested on every context), then each context's specialists."""
    trials = grid(spec, "general", "train", "train")
    for i in range(spec.num_contexts):
        name = _own_set(i)
        trials += [
            Trial(
                f"specialist{i}-{variant}-s{seed}", "specialist", variant, seed, name, name, "train"
            )
            for variant in spec.variants
            for seed in range(spec.seeds)
        ]
    return trials


def _per_seed_text(stats: GapStatistics) -> str:
    seeds = stats.per_seed()
    return (
        "Mean return per seed over its contexts: "
        + "; ".join(
            f"{name} " + ", ".join(f"{v:.1f}" for v in values) for name, values in seeds.items()
        )
        + "."
    )


def _sections(spec: OptimalityGapSpec, plan: Plan, cells: pd.DataFrame, curves) -> list[Section]:
    sections = []
    for variant, stats in gap_statistics(cells, spec.variants, **spec.design).items():
        g, s = stats.general, stats.specialists
        best = float(max(g.values.max(), s.values.max()))
        finished = stats.finished
        per_context = metrics.per_context_gap(g.matrix, s.matrix)
        varying = plan.spec.space().varying(plan.sets["train"].contexts)
        feature = varying[0] if varying else None
        for row in stats.aggregates:
            row["fraction at best return"] = finished[row["agent"]]
        both = {"general": g, "specialists": s}
        intervals = (
            f"95% bootstrap CIs over {design_words(both, spec.test_contexts)} "
            f"({spec.bootstrap_reps} replicates, seed {spec.seed})"
            if has_interval(both)
            else f"Points only: {ONE_SEED}"
        )
        text = [
            f"Variant {variant}: one general agent trained on {spec.num_contexts} contexts vs one "
            f"specialist per context; each evaluated on the context(s) it was trained on "
            f"({spec.eval_episodes} episodes, {spec.seeds} seeds). {intervals}.",
            f"Optimality gap E_c[G_specialist(c) − G_general(c)] = {stated(stats.gap, both)}.",
            "Specialists minus the general agent: "
            + ", ".join(f"{name} {stated(d, both)}" for name, d in stats.differences.items())
            + ".",
            "Probability that a specialist beats the general agent on a context: "
            f"{stated(stats.improvement, both)}.",
            _per_seed_text(stats),
            f"Fraction of run×context returns at the best return observed in the run ({best:g}; "
            f"within 1% of the observed return range, i.e. ≥ {finished['threshold']:g}): "
            f"general {finished['general']:.2f}, specialists {finished['specialists']:.2f} "
            f"(difference {stated(finished['difference'], both)}).",
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
                plots.intervals(
                    drawn_intervals(stats.intervals, both),
                    title=interval_title("Aggregate return", both, spec.test_contexts),
                ),
                f"Mean, median and IQM ({interval_words(both, spec.test_contexts)})",
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
            Section(
                f"Optimality gap ({variant})", text, [("Aggregates", stats.aggregates)], figures
            )
        )
    if not sections:
        sections.append(Section("Optimality gap", ["Not enough finished trials for the gap."]))
    return sections


register_protocol(Protocol(OptimalityGapSpec, _sections, _expand, _outline))
