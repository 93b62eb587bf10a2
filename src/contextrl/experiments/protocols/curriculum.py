"""The curriculum protocol: the same agent trained on a fixed pool of contexts spread over whole
feature ranges and under SPaCE, ADR and PLR (:mod:`contextrl.context.curricula`), then tested on a
grid of contexts that reaches the ranges' ends.

"uniform" trains on the pool as it is (round robin: every member equally often); SPaCE and PLR draw
from the same pool with the weights they learn; ADR widens ranges from the default value towards the
same whole ranges. Every agent is tested on the same grid.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import jax
import numpy as np
import pandas as pd

from contextrl.agents import dqn, ppo, sac
from contextrl.analysis import metrics, plots
from contextrl.analysis.intervals import FIXED, two_sample_ci
from contextrl.analysis.report import Section
from contextrl.analysis.scores import (
    Scores,
    has_interval,
    interval_title,
    interval_words,
    learned,
    score_intervals,
    score_matrices,
    stated,
)
from contextrl.context.curricula import ADR, PLR, SPaCE
from contextrl.context.distributions import draw
from contextrl.context.features import ContextError
from contextrl.experiments.plan import TRAIN_KEY, ContextSet, Plan, Trial, draw_set
from contextrl.experiments.protocol import Protocol, register_protocol
from contextrl.experiments.reports import figure
from contextrl.experiments.spec import (
    CommonSpec,
    SpecError,
    check_int,
    check_number,
    feature_ranges,
    merge_features,
    parse_assignments,
)

CURRICULA = ("uniform", "space", "adr", "plr")
RULE = (
    "Decision rule, fixed before any run: a curriculum does better than the uniform pool where the "
    "95% interval of the difference in mean test return over the grid (each curriculum's seeds "
    "resampled apart, each seed with its whole grid) lies above zero, worse where it lies below "
    "zero, and is not told apart at this budget otherwise. A pair in which either side's agents did "
    "not clearly beat a random policy on their training contexts gets no verdict, and one seed "
    "gives none."
)


@dataclasses.dataclass(frozen=True)
class CurriculumSpec(CommonSpec):
    """A fixed uniform pool against curricula over whole ranges, tested on a grid (their ends).

    ``ranges`` maps each feature to its whole [low, high]; the pool is ``num_train_contexts`` drawn
    uniformly from them; the test grid has ``test_points`` values per feature, ends included.
    ``adr_thresholds`` is ADR's [narrow_below, widen_above] in return units. ``curriculum_options``
    maps a curriculum to keyword options of its class (e.g. ``{plr: {temperature: 0.3}}``).
    """

    protocol: str = "curriculum"
    variants: tuple[str, ...] = ("concat_varying",)
    curricula: tuple[str, ...] = CURRICULA
    ranges: dict | None = None  # None: the environment's default (spec.ENV_DEFAULTS)
    adr_thresholds: list | None = None
    env_defaults = ("ranges", "adr_thresholds")
    num_train_contexts: int = 64
    test_points: int = 11
    curriculum_options: dict = dataclasses.field(default_factory=dict)

    test_contexts = FIXED  # the claim is about the grid tested, ends included
    vary_field = "ranges"

    def validate(self) -> None:
        super().validate()
        if self.agent_entry().make_train not in (ppo.make_train, dqn.make_train, sac.make_train):
            raise SpecError(
                "agent: curricula run in the compiled training loops of PPO, DQN/C51 and SAC "
                f"(ppo, dqn, c51, sac), got {self.agent!r}"
            )
        if "plr" in self.curricula and self.agent_entry().make_train is not ppo.make_train:
            raise SpecError(
                "curricula: PLR scores contexts by the positive advantage of a rollout's steps, "
                f"which only PPO's loop computes; drop plr or train with ppo (agent {self.agent!r})"
            )
        if not self.curricula or len(set(self.curricula)) != len(self.curricula):
            raise SpecError(f"curricula: give distinct names from {list(CURRICULA)}")
        for name in self.curricula:
            if name not in CURRICULA:
                raise SpecError(f"curricula: unknown {name!r}; choose from {list(CURRICULA)}")
        if "space" in self.curricula and "hidden" in self.variants:
            raise SpecError(
                "variants: SPaCE orders contexts by the critic's value of their start states, which "
                "an agent that does not see the context cannot tell apart; drop hidden or space"
            )
        check_int("num_train_contexts", self.num_train_contexts, 2)
        check_int("test_points", self.test_points, 2)
        self.boxes()
        thresholds = self.adr_thresholds
        if not isinstance(thresholds, (list, tuple)) or len(thresholds) != 2:
            raise SpecError(f"adr_thresholds: give [narrow_below, widen_above], got {thresholds!r}")
        for value in thresholds:
            check_number("adr_thresholds", value)
        if not isinstance(self.curriculum_options, Mapping):
            raise SpecError(
                "curriculum_options: give a mapping curriculum -> options, got "
                f"{self.curriculum_options!r}"
            )
        for name, options in self.curriculum_options.items():
            if name not in self.curricula or name == "uniform":
                raise SpecError(
                    f"curriculum_options: {name!r} is not a curriculum of this run "
                    f"({[c for c in self.curricula if c != 'uniform']})"
                )
            if not isinstance(options, Mapping):
                raise SpecError(f"curriculum_options.{name}: give a mapping, got {options!r}")
        pool = _pool(self)
        for name in self.curricula:
            if name != "uniform":
                self.make_curriculum(name, pool)

    def boxes(self) -> dict[str, tuple[float, float]]:
        """Canonical feature names → (low, high), checked against the feature bounds."""
        if not isinstance(self.ranges, Mapping) or not self.ranges:
            raise SpecError(f"ranges: give features with [low, high], got {self.ranges!r}")
        return feature_ranges(self.space(), "ranges", self.ranges)

    def make_curriculum(self, name: str, pool):
        """The curriculum ``name`` over ``pool`` (ADR over the whole ranges), options applied."""
        options = dict(self.curriculum_options.get(name, {}))
        size = len(pool)
        try:
            if name == "space":
                steps = max(1, size // 8)
                return SPaCE(pool, **{"initial": steps, "step": steps, **options})
            if name == "plr":
                return PLR(pool, **options)
            if name == "adr":
                narrow_below, widen_above = (float(v) for v in self.adr_thresholds)
                return ADR(
                    self.space(),
                    self.boxes(),
                    widen_above=widen_above,
                    narrow_below=narrow_below,
                    **options,
                )
        except (ContextError, TypeError) as error:
            raise SpecError(f"curriculum_options.{name}: {error}") from None
        raise SpecError(f"curricula: unknown {name!r}; choose from {list(CURRICULA)}")


def _pool(spec: CurriculumSpec):
    features = {name: {"uniform": list(ends)} for name, ends in spec.boxes().items()}
    return draw_set(spec, "ranges", features, spec.num_train_contexts, TRAIN_KEY)


def _grid_values(spec: CurriculumSpec) -> dict[str, np.ndarray]:
    """Each feature's test values over the grid (every combination, ends included)."""
    axes = [np.linspace(low, high, spec.test_points) for low, high in spec.boxes().values()]
    mesh = np.meshgrid(*axes, indexing="ij")
    return {name: m.ravel().astype(np.float32) for name, m in zip(spec.boxes(), mesh, strict=True)}


def _trials(spec: CurriculumSpec) -> list[Trial]:
    return [
        Trial(
            f"{name}-{variant}-s{seed}",
            name,
            variant,
            seed,
            "pool",
            "test",
            curriculum="" if name == "uniform" else name,
        )
        for name in spec.curricula
        for variant in spec.variants
        for seed in range(spec.seeds)
    ]


def _expand(spec: CurriculumSpec) -> tuple[dict, list]:
    values = _grid_values(spec)
    size = len(next(iter(values.values())))
    test = draw(spec.space(), {}, size, jax.random.key(0)).replace(**values)
    sets = {"pool": ContextSet("pool", _pool(spec)), "test": ContextSet("test", test)}
    return sets, _trials(spec)


def _outline(spec: CurriculumSpec) -> tuple[dict, list]:
    tests = spec.test_points ** len(spec.boxes())
    return {"pool": spec.num_train_contexts, "test": tests}, _trials(spec)


def _learned(training: pd.DataFrame) -> dict[tuple[str, str], bool]:
    """(curriculum, variant) → whether its agents clearly beat a random policy on the pool."""
    means = training.groupby(["kind", "variant"])[["train_return", "random_return"]].mean()
    return {key: learned(*row) for key, row in means.iterrows()}


def _verdict(interval, pair: Mapping[str, Scores], both_learned: bool) -> str:
    if not both_learned:
        return "no verdict: an agent did not beat a random policy"
    if not has_interval(pair):
        return "no verdict with one seed"
    if interval.low > 0:
        return "better than uniform"
    if interval.high < 0:
        return "worse than uniform"
    return "not told apart at this budget"


def _range_panels(spec: CurriculumSpec, plan: Plan, curves: pd.DataFrame) -> dict:
    """Per curriculum and feature: the training values it drew from over time (mean over seeds).

    ADR: its range's ends. A pool curriculum: the 10th, 50th and 90th percentile of the feature
    under its weights over the pool.
    """
    pool = plan.sets["pool"].contexts
    panels = {}
    for name in spec.curricula:
        rows = curves[curves["kind"] == name]
        if name == "uniform" or rows.empty:
            continue
        by_step = rows.groupby("step").mean(numeric_only=True)
        steps = by_step.index.to_numpy(float)
        for index, feature in enumerate(spec.boxes()):
            if name == "adr":
                lines = {
                    "low": by_step[f"curriculum.low.{index}"],
                    "high": by_step[f"curriculum.high.{index}"],
                }
            else:
                weights = by_step[[f"curriculum.weights.{i}" for i in range(len(pool))]].to_numpy()
                lines = _weighted_percentiles(np.asarray(getattr(pool, feature)), weights)
            panels[f"{name}: {feature}"] = {
                label: (steps, np.asarray(values)) for label, values in lines.items()
            }
    return panels


def _weighted_percentiles(values: np.ndarray, weights: np.ndarray) -> dict[str, np.ndarray]:
    """The 10th, 50th and 90th percentile of ``values`` under each row of ``weights``."""
    order = np.argsort(values)
    cumulative = np.cumsum(weights[:, order], axis=1)
    cumulative /= cumulative[:, -1:]
    out = {}
    for q in (10, 50, 90):
        picked = np.argmax(cumulative >= q / 100 - 1e-9, axis=1)
        out[f"p{q}"] = values[order][picked]
    return out


def _sections(
    spec: CurriculumSpec, plan: Plan, cells: pd.DataFrame, curves, training: pd.DataFrame
) -> list[Section]:
    labels = cells["kind"].astype(str) + ", " + cells["variant"].astype(str)
    scores = score_matrices(cells, labels)
    design = dict(contexts=spec.test_contexts, reps=spec.bootstrap_reps, seed=spec.seed)
    _, rows = score_intervals(scores, **design)
    ok = _learned(training) if not training.empty else {}
    verdicts = []
    for name in spec.curricula:
        for variant in spec.variants:
            mine, base = scores.get(f"{name}, {variant}"), scores.get(f"uniform, {variant}")
            if name == "uniform" or mine is None or base is None:
                continue
            if not (mine.present and base.present):
                continue
            pair = {f"{name}, {variant}": mine, f"uniform, {variant}": base}
            difference = two_sample_ci(
                mine.matrix,
                base.matrix,
                metrics.difference_of_means,
                units=(mine.unit, base.unit),
                **design,
            )
            both = ok.get((name, variant), False) and ok.get(("uniform", variant), False)
            verdicts.append(
                {
                    "curriculum": name,
                    "variant": variant,
                    "mean test return − uniform's": stated(difference, pair),
                    "verdict": _verdict(difference, pair, both),
                }
            )
    boxes = spec.boxes()
    ranges = ", ".join(f"{name} in [{low:g}, {high:g}]" for name, (low, high) in boxes.items())
    text = [
        f"{spec.agent} agents ({spec.seeds} seeds per curriculum) trained on {ranges}: uniform on "
        f"a pool of {spec.num_train_contexts} contexts drawn uniformly from the ranges, SPaCE and "
        "PLR weighting the same pool, ADR widening each range from the default value. Every agent "
        f"is tested on a grid of {spec.test_points} values per feature, ends included "
        f"({spec.eval_episodes} episodes per context).",
        RULE,
    ]
    over = interval_words(scores, spec.test_contexts)
    figures = []  # test return against each feature: the shared per-context section
    panels = _range_panels(spec, plan, curves) if not curves.empty else {}
    if panels:
        figures.append(
            figure(
                "curriculum-over-training",
                plots.schedules(panels, xlabel="environment steps"),
                "What each curriculum trained on over time (mean over seeds): ADR's range ends; "
                "for SPaCE and PLR the 10th, 50th and 90th percentile of the feature under their "
                "weights over the pool",
            )
        )
    tables = [(interval_title("Test return over the grid", scores, spec.test_contexts), rows)]
    if verdicts:
        tables.append((f"Each curriculum against the uniform pool ({over})", verdicts))
    return [Section("Curricula", text, tables, figures)]


def _vary(data: dict, items: list[str]) -> str | None:
    """``--vary FEATURE=[LOW,HIGH]`` sets a feature's whole range, on top of a config's."""
    return merge_features(data, "ranges", parse_assignments(items, "--vary", "FEATURE=[LOW,HIGH]"))


register_protocol(
    Protocol(
        CurriculumSpec,
        _sections,
        _expand,
        _outline,
        vary=_vary,
        per_context_intervals=False,  # its own table shows the intervals
        reads_training=True,
    )
)
