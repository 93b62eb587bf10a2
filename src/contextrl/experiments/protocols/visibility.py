"""The visibility protocol (paper §6.3): agents that see the context in different ways (hidden,
concatenated, gated) trained on the same contexts and tested on held-out ones."""

from __future__ import annotations

import dataclasses

import pandas as pd

from contextrl.analysis import metrics, plots
from contextrl.analysis.intervals import two_sample_ci
from contextrl.analysis.report import Section
from contextrl.analysis.scores import (
    drawn_intervals,
    has_interval,
    interval_title,
    interval_words,
    score_intervals,
    score_matrices,
    stated,
)
from contextrl.experiments.plan import Plan, grid, train_and_test_sets, train_and_test_sizes
from contextrl.experiments.protocol import Protocol, register_protocol
from contextrl.experiments.reports import figure
from contextrl.experiments.spec import CommonSpec, check_int


@dataclasses.dataclass(frozen=True)
class VisibilitySpec(CommonSpec):
    """Hidden vs visible context: training curves and returns on held-out contexts (paper §6.3)."""

    protocol: str = "visibility"

    variants: tuple[str, ...] = ("hidden", "concat_all", "concat_varying")
    train: dict | None = None  # None: the environment's default (spec.ENV_DEFAULTS)
    env_defaults = ("train",)
    test: dict | None = None  # None: held-out contexts from the training distribution
    num_train_contexts: int = 64
    num_test_contexts: int = 64

    def validate(self) -> None:
        super().validate()
        check_int("num_train_contexts", self.num_train_contexts, 1)
        check_int("num_test_contexts", self.num_test_contexts, 1)
        self.resolve_features("train", self.train)
        if self.test is not None:
            self.resolve_features("test", self.test)


def _expand(spec: VisibilitySpec) -> tuple[dict, list]:
    return train_and_test_sets(spec), grid(spec, "visibility", "train", "test")


def _outline(spec: VisibilitySpec) -> tuple[dict, list]:
    return train_and_test_sizes(spec), grid(spec, "visibility", "train", "test")


def _sections(spec: VisibilitySpec, plan: Plan, cells: pd.DataFrame, curves) -> list[Section]:
    scores = score_matrices(cells, cells["variant"])
    contexts = spec.test_contexts
    cis, rows = score_intervals(scores, **spec.design)
    text = [
        f"{spec.agent} agents with context visibility {list(spec.variants)} trained on "
        f"{spec.num_train_contexts} contexts and tested on {spec.num_test_contexts} held-out contexts "
        f"({spec.seeds} seeds, {spec.eval_episodes} episodes each)."
    ]
    hidden = scores.get("hidden")
    for name, other in scores.items():
        if hidden is None or name == "hidden" or not (hidden.present and other.present):
            continue
        poi = two_sample_ci(
            other.matrix,
            hidden.matrix,
            metrics.probability_of_improvement,
            units=(other.unit, hidden.unit),
            contexts=contexts,
            reps=spec.bootstrap_reps,
            seed=spec.seed,
        )
        pair = {name: other, "hidden": hidden}
        if has_interval(pair):
            text.append(f"P({name} > hidden) = {poi} ({interval_words(pair, contexts)})")
        else:
            text.append(f"P({name} > hidden) = {stated(poi, pair)}")
    returns = {name: s.values for name, s in scores.items() if s.present}
    figures = [
        figure("test-ecdf", plots.ecdf(returns, title="Test returns"), "eCDF of test returns"),
        figure("test-histogram", plots.histograms(returns, title="Test returns"), "Test returns"),
        figure(
            "test-intervals",
            plots.intervals(
                drawn_intervals(cis, scores), title=interval_title("Test return", scores, contexts)
            ),
            f"Aggregate test return ({interval_words(scores, contexts)})",
        ),
    ]
    return [Section("Context visibility", text, [("Test return", rows)], figures)]


register_protocol(  # per_context_intervals: its own table shows them
    Protocol(VisibilitySpec, _sections, _expand, _outline, per_context_intervals=False)
)
