"""The paper's figures as runnable specs (``contextrl paper``).

Each figure's spec ships in ``contextrl/paper/<figure>.yaml`` (a figure of two runs, such as PB2 with
the context hidden and visible, has one file per part), its header stating the paper's section and
claim. A figure here adds the check that decides the claim from the finished runs, with the interval
that decides it, and a smaller budget for two CPU cores. Runs go to ``<root>/<figure>-<scale>/<part>``,
so the results page (:func:`results_page`) is regenerated from the run folders at any time. The
project keeps its own runs' records in ``results/paper`` (their checkpoints and figures left out), so
``docs/paper.md`` is regenerated from the repository alone.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import os
import re
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import jax
import numpy as np
import pandas as pd
import yaml

from contextrl.agents import ConfigError
from contextrl.analysis import metrics
from contextrl.analysis.intervals import SAMPLED, SEEDS, Interval, bootstrap_ci, two_sample_ci
from contextrl.analysis.report import Figure as ReportFigure
from contextrl.analysis.report import Section, render
from contextrl.experiments.analyze import (
    LEARNED_MARGIN,
    design_words,
    learned,
    run_cells,
    score_matrices,
)
from contextrl.experiments.optimality_gap import gap_statistics
from contextrl.experiments.planning import duration
from contextrl.experiments.protocols import expand
from contextrl.experiments.runner import resume, run_experiment
from contextrl.experiments.runs import RunDir, write_text
from contextrl.experiments.sensitivity import magnitude_lines
from contextrl.experiments.spec import SpecError, load_yaml, parse_spec, spec_to_dict
from contextrl.experiments.train_test import REGIONS

SPEC_FOLDER = Path(__file__).resolve().parents[1] / "paper"
SCALES = ("paper", "small", "tiny")
PAPER_RUNS = "results/paper"
# The repository's kept runs, where the package is installed from a checkout (editable)
REPOSITORY_RUNS = SPEC_FOLDER.parents[2] / PAPER_RUNS


def kept_runs() -> Path:
    """Where ``contextrl paper list|page`` reads runs when not told: ./results/paper, else the
    repository's (a checkout the package is installed from); refused, saying where it looked,
    when neither holds runs."""
    for folder in (Path(PAPER_RUNS), REPOSITORY_RUNS):
        if any(folder.glob("*/*/spec.yaml")):
            return folder
    raise SpecError(
        f"contextrl paper: no runs in ./{PAPER_RUNS} or {REPOSITORY_RUNS}; give --runs FOLDER "
        "(the repository keeps its runs in results/paper; contextrl paper run writes new ones)"
    )


# The decision rules, fixed before any run. A verdict needs this many seeds (the unit of replication)
MIN_SEEDS = 5
# "No difference" holds inside ± this fraction of the agents' gain over a random policy at their
# training contexts; a "better" claim does not hold when the difference stays below it.
EQUIVALENCE = 0.10
# A feature is harmless when its drop stays below HARMLESS × the gain, brittle above BRITTLE ×.
HARMLESS, BRITTLE = 0.10, 0.50
GATE = (
    f"No verdict from fewer than {MIN_SEEDS} seeds, or where an agent does not beat a random policy "
    f"at its training contexts by {LEARNED_MARGIN:.0%} of max(|random return|, 1)."
)


@dataclasses.dataclass(frozen=True)
class Verdict:
    """Whether a claim holds at the budget it ran at (None: the intervals do not decide it), or,
    where ``withheld`` says why, no verdict at all: the evidence and what its intervals alone would
    say (``holds``) are then shown, not judged."""

    holds: bool | None
    evidence: str
    withheld: str = ""

    @property
    def word(self) -> str:
        if self.withheld:
            return "no verdict"
        return {True: "holds", False: "does not hold", None: "undecided"}[self.holds]


@dataclasses.dataclass(frozen=True)
class Learning:
    """The figure's agents at their training contexts against a random policy's on the same ones:
    per variant and kind, (trained, random) mean returns; ``gain`` is their mean difference."""

    returns: dict[str, tuple[float, float]]

    @property
    def gain(self) -> float:
        return float(np.mean([trained - random for trained, random in self.returns.values()]))

    def failed(self) -> list[str]:
        return [name for name, pair in self.returns.items() if not learned(*pair)]

    def __str__(self) -> str:
        return "trained vs random return at the training contexts: " + ", ".join(
            f"{name} {trained:.4g} vs {random:.4g}"
            for name, (trained, random) in self.returns.items()
        )


def learning(runs: Mapping[str, RunDir]) -> Learning:
    """Per variant and agent kind over the figure's runs, the trained and the random policy's mean
    return on the training contexts (what the run's "Did the agents learn?" section shows)."""
    frames = [frame for frame in (run.training() for run in runs.values()) if not frame.empty]
    if not frames:
        return Learning({})
    frame = pd.concat(frames, ignore_index=True)
    several_kinds = frame["kind"].nunique() > 1
    returns = {}
    for (variant, kind), group in frame.groupby(["variant", "kind"], sort=False):
        name = f"{kind}, {variant}" if several_kinds else str(variant)
        returns[name] = (float(group["train_return"].mean()), float(group["random_return"].mean()))
    return Learning(returns)


def _seeds(runs: Mapping[str, RunDir]) -> int:
    """The fewest independently trained seeds among the runs' results (a PB2 run: its one best
    member)."""
    return min(int(run.results()["seed"].nunique()) for run in runs.values())


@dataclasses.dataclass(frozen=True)
class Check:
    """A claim's decision rule: ``rule`` says it (each spec file's ``# Decision:`` line, and the
    page), ``decide(runs, gain)`` applies it to the finished runs. ``gated``: the learnability gate
    and the seed floor apply (every figure that trains agents)."""

    rule: str
    decide: Callable[[Mapping[str, RunDir], float], Verdict]
    gated: bool = True

    def __call__(self, runs: Mapping[str, RunDir]) -> Verdict:
        """The verdict, or no verdict with the reason, always with the evidence and, for agents
        that train, their trained and random returns."""
        if not self.gated:
            return self.decide(runs, np.nan)
        learned_ = learning(runs)
        found = self.decide(runs, learned_.gain if learned_.returns else np.nan)
        spec = next(iter(runs.values())).spec()
        if not spec.agent_entry().trained:
            return Verdict(found.holds, found.evidence, f"the {spec.agent} agent does not learn")
        evidence = f"{found.evidence}; {learned_}"
        reasons = []
        seeds = _seeds(runs)
        if seeds < MIN_SEEDS:
            reasons.append(f"{seeds} seeds, fewer than {MIN_SEEDS}")
        failed = learned_.failed()
        if not learned_.returns or failed:
            which = ", ".join(failed) or "no agent has a training record"
            reasons.append(f"the agent did not learn at this budget: {which}")
        return Verdict(found.holds, evidence, "; ".join(reasons))


def _decide(interval: Interval, above: float = 0.0) -> bool | None:
    """True when the interval lies above ``above``, False when below, else None."""
    if interval.low > above:
        return True
    if interval.high < above:
        return False
    return None


def _all(decisions: list[bool | None]) -> bool | None:
    """Every part holds: True; some part fails: False; else undecided."""
    if False in decisions:
        return False
    return True if all(d is True for d in decisions) else None


def _cells(run: RunDir):
    spec = run.spec()
    return spec, run_cells(run, _plan(spec), run.results())


def gap_check(at_least: float, finished: bool = False) -> Check:
    """Specialists beat the general agent by more than ``at_least`` in mean, median and IQM (and,
    where ``finished``, reach the best return in more cells: the paper's finished episodes)."""
    parts = "mean, median and IQM" + (" and the fraction of finished episodes" if finished else "")
    rule = (
        f"holds when the 95% intervals of the specialists' minus the general agent's mean, median "
        f"and IQM test return all lie above {at_least:g}"
        + (
            " and that of the fraction of finished episodes (cells at the best return) above 0"
            if finished
            else ""
        )
        + "; does not hold when one of them lies below; undecided otherwise. Intervals resample "
        "the general agent's seeds (each with all its contexts) and the contexts, each with its "
        f"specialists ({parts})."
    )

    def decide(runs: Mapping[str, RunDir], gain: float) -> Verdict:
        (run,) = runs.values()
        spec, cells = _cells(run)
        stats = gap_statistics(spec, cells)[spec.variants[0]]
        seeds = stats.per_seed()
        decisions = [_decide(d, at_least) for d in stats.differences.values()]
        done = stats.finished
        text = (
            "specialists − general: "
            + ", ".join(f"{name} {d}" for name, d in stats.differences.items())
            + f" (95% CI; each needs to lie above {at_least:g}); "
        )
        if finished:
            decisions.append(_decide(done["difference"]))
            relative = 1 - done["general"] / done["specialists"] if done["specialists"] else np.nan
            text += (
                f"finished episodes (return ≥ {done['threshold']:.4g}): general "
                f"{done['general']:.2f}, specialists {done['specialists']:.2f}, difference "
                f"{done['difference']} (needs to lie above 0; the paper: about 40% fewer for the "
                f"general agent, here {relative:.0%}); "
            )
        text += (
            f"P(specialist > general) = {stats.improvement}; mean return per seed: general "
            f"{_numbers(seeds['general'])}, specialists {_numbers(seeds['specialists'])}"
        )
        return Verdict(_all(decisions), text)

    return Check(rule, decide)


def _numbers(values) -> str:
    return " ".join(f"{v:.0f}" for v in values)


def _variant_difference(runs: Mapping[str, RunDir], a: str, b: str) -> tuple[dict, Interval, str]:
    """Score matrices by variant over all the figure's runs (a part per variant, or one run), the
    mean test return of variant ``a`` minus ``b`` with its interval, and what it resampled."""
    scores, spec = {}, None
    for run in runs.values():
        spec, cells = _cells(run)
        scores.update(score_matrices(cells, cells["variant"]))
    diff = two_sample_ci(
        scores[a].matrix,
        scores[b].matrix,
        metrics.difference_of_means,
        units=(scores[a].unit, scores[b].unit),
        contexts=spec.test_contexts,
        reps=spec.bootstrap_reps,
        seed=spec.seed,
    )
    return scores, diff, design_words({a: scores[a], b: scores[b]}, spec.test_contexts)


def _means(scores: dict, a: str, b: str) -> str:
    return ", ".join(f"{v} {metrics.aggregate_mean(scores[v].matrix):.4g}" for v in (a, b))


def _difference_check(
    a: str, b: str, rule: str, decide: Callable[[Interval, float], bool | None], bounds: str
) -> Check:
    """A claim about mean test return ``a`` − ``b``: ``decide(interval, margin)`` says whether it
    holds, the margin being EQUIVALENCE × the agents' gain; ``bounds`` (formatted with ``margin``
    and ``gain``) says where the evidence stands against it."""

    def check(runs: Mapping[str, RunDir], gain: float) -> Verdict:
        scores, diff, over = _variant_difference(runs, a, b)
        margin = EQUIVALENCE * gain
        return Verdict(
            decide(diff, margin),
            f"mean test return {a} − {b} = {diff} (95% CI over {over}; "
            + bounds.format(margin=margin, gain=gain)
            + "); "
            + _means(scores, a, b),
        )

    return Check(rule, check)


def better_check(a: str, b: str) -> Check:
    """Variant ``a``'s mean test return is above ``b``'s; not better by a meaningful amount when
    the interval lies below the equivalence margin."""

    def decide(diff: Interval, margin: float) -> bool | None:
        return True if diff.low > 0 else (False if diff.high < margin else None)

    rule = (
        f"holds when the 95% interval of mean test return {a} − {b} lies above 0; does not hold "
        f"when it lies below {EQUIVALENCE:.0%} of the agents' gain over a random policy at their "
        "training contexts (not better by a meaningful amount); undecided otherwise."
    )
    return _difference_check(a, b, rule, decide, "holds above 0, does not hold below {margin:.4g}")


def similar_check(a: str, b: str) -> Check:
    """No meaningful difference between the mean test returns of ``a`` and ``b``: equivalence
    within a margin fixed before the run, so more seeds can only sharpen the verdict."""

    def decide(diff: Interval, margin: float) -> bool | None:
        if -margin < diff.low and diff.high < margin:
            return True
        return False if diff.low > margin or diff.high < -margin else None

    rule = (
        f"holds when the 95% interval of mean test return {a} − {b} lies inside ± "
        f"{EQUIVALENCE:.0%} of the agents' gain over a random policy at their training contexts; "
        "does not hold when it lies outside that margin; undecided otherwise."
    )
    bounds = f"the margin ± {{margin:.4g}} = {EQUIVALENCE:.0%} of the gain {{gain:.4g}}"
    return _difference_check(a, b, rule, decide, bounds)


def _drop(runs: np.ndarray, default_column: int) -> np.ndarray:
    """How far the worst magnitude's mean return falls below the default's (``runs``: seeds ×
    magnitudes, with any leading axes of bootstrap samples)."""
    means = np.ma.filled(np.ma.mean(runs, axis=-2), np.nan)
    return means[..., default_column] - np.nanmin(means, axis=-1)


def _zone(drop: Interval, gain: float) -> str | None:
    """harmless, moderate or brittle where the drop's interval lies in one zone, else None."""
    if drop.high < HARMLESS * gain:
        return "harmless"
    if drop.low > BRITTLE * gain:
        return "brittle"
    if drop.low > HARMLESS * gain and drop.high < BRITTLE * gain:
        return "moderate"
    return None


def sensitivity_check(harmless: tuple[str, ...] = (), brittle: tuple[str, ...] = ()) -> Check:
    """The named features are harmless or brittle (none named: at least one of each exists).

    A feature's drop is the default context's mean return minus its worst magnitude's, with an
    interval over seeds (each seed's agent keeps all its magnitudes: the sweep is a fixed set)."""
    zones = (
        f"A feature is harmless when the 95% interval of its drop (the default context's mean "
        f"return minus its worst magnitude's, over seeds) lies below {HARMLESS:.0%} of the agent's "
        f"gain over a random policy at the default context, brittle when it lies above "
        f"{BRITTLE:.0%}, moderate when it lies between; "
    )
    if harmless or brittle:
        rule = zones + (
            f"holds when {', '.join(harmless)} are harmless and {', '.join(brittle)} brittle; does "
            f"not hold when one of them is shown otherwise (a harmless one's drop above "
            f"{HARMLESS:.0%}, a brittle one's below {BRITTLE:.0%}); undecided otherwise."
        )
    else:
        rule = zones + (
            f"holds when some feature is harmless and some brittle; does not hold when every "
            f"feature's drop lies above {HARMLESS:.0%} (none harmless) or every one below "
            f"{BRITTLE:.0%} (none brittle); undecided otherwise."
        )

    def decide(runs: Mapping[str, RunDir], gain: float) -> Verdict:
        (run,) = runs.values()
        spec, cells = _cells(run)
        drops = {}
        for feature, by_variant in magnitude_lines(cells).items():
            x, matrix = by_variant[spec.variants[0]]
            column = int(np.flatnonzero(np.isclose(x, 1.0))[0])
            drops[feature] = bootstrap_ci(
                matrix,
                lambda m, column=column: _drop(m, column),
                unit=SEEDS,
                contexts=spec.test_contexts,
                reps=spec.bootstrap_reps,
                seed=spec.seed,
            )
        if not np.isfinite(gain) or gain <= 0:
            named = ", ".join(f"{f} {d}" for f, d in drops.items())
            return Verdict(
                None, f"drop per feature (95% CI over seeds): {named}; no gain to scale by"
            )
        zone = {f: _zone(d, gain) for f, d in drops.items()}
        not_harmless = {f for f, d in drops.items() if d.low > HARMLESS * gain}
        not_brittle = {f for f, d in drops.items() if d.high < BRITTLE * gain}

        def named(feature: str, wanted: str, ruled_out: set[str]) -> bool | None:
            """In the wanted zone: True; its interval rules that out: False; else undecided."""
            if zone.get(feature) == wanted:
                return True
            return False if feature in ruled_out else None

        if harmless or brittle:
            holds = _all(
                [named(f, "harmless", not_harmless) for f in harmless]
                + [named(f, "brittle", not_brittle) for f in brittle]
            )
        else:
            found = set(zone.values())
            if {"harmless", "brittle"} <= found:
                holds = True
            elif not_harmless == set(drops) or not_brittle == set(drops):
                holds = False
            else:
                holds = None
        named = ", ".join(f"{f} {d}" + (f" {zone[f]}" if zone[f] else "") for f, d in drops.items())
        return Verdict(
            holds,
            f"drop from the default context to the worst magnitude per feature (95% CI over "
            f"seeds): {named}; harmless below {HARMLESS * gain:.4g}, brittle above "
            f"{BRITTLE * gain:.4g} ({HARMLESS:.0%} and {BRITTLE:.0%} of the gain {gain:.4g})",
        )

    return Check(rule, decide)


def _per_seed(cells: pd.DataFrame) -> pd.Series:
    """Each seed's mean return over ``cells`` (all its agents' cells there)."""
    return cells.groupby("seed")["return"].mean()


def _seed_interval(values: np.ndarray, spec) -> Interval:
    """The mean of per-seed values with its interval over seeds."""
    return bootstrap_ci(
        values[:, None],
        metrics.aggregate_mean,
        unit=SEEDS,
        reps=spec.bootstrap_reps,
        seed=spec.seed,
    )


def kirk_check(combinatorial: bool = True, concat_extrapolates: bool = False) -> Check:
    """Kirk et al.'s protocol (§6.4): for every variant, returns fall from interpolation to
    extrapolation (both features outside the training range); where ``combinatorial``, also to the
    combinatorial-interpolation contexts of modes B and C; where ``concat_extrapolates``, the concat
    agent returns more than the hidden one on the extrapolation contexts."""
    parts = ["interpolation − extrapolation (both features) per seed, for every variant"]
    if combinatorial:
        parts.append(
            "interpolation (every mode) − combinatorial interpolation (modes B and C) per seed"
        )
    if concat_extrapolates:
        parts.append("concat − hidden on the extrapolation contexts (one or both features)")
    rule = (
        "holds when the 95% intervals (over seeds, each seed's agents with all their contexts) of "
        + "; of ".join(parts)
        + " all lie above 0; does not hold when one lies below 0; undecided otherwise."
    )

    def decide(runs: Mapping[str, RunDir], gain: float) -> Verdict:
        (run,) = runs.values()
        spec, cells = _cells(run)
        decisions, text = [], []

        def paired(name: str, first: pd.DataFrame, second: pd.DataFrame) -> None:
            diff = (_per_seed(first) - _per_seed(second)).dropna()
            if diff.empty:
                decisions.append(None)
                text.append(f"{name}: no seed has returns on both")
                return
            found = _seed_interval(diff.to_numpy(float), spec)
            decisions.append(_decide(found))
            text.append(f"{name} = {found}")

        for variant in spec.variants:
            mine = cells[cells["variant"] == variant]
            inside = mine[mine["region"] == REGIONS[0]]
            paired(
                f"{variant}: interpolation − extrapolation (both)",
                inside,
                mine[mine["region"] == REGIONS[3]],
            )
            if combinatorial:  # modes B and C have the combinatorial contexts (C: no other inside)
                modes = mine[mine["kind"].isin(["modeB", "modeC"])]
                paired(
                    f"{variant}: interpolation − combinatorial (modes B, C)",
                    inside,
                    modes[modes["region"] == REGIONS[1]],
                )
        if concat_extrapolates:
            outside = cells[cells["region"].isin(REGIONS[2:])]
            concat, hidden = (
                _per_seed(outside[outside["variant"] == v]).dropna().to_numpy(float)
                for v in ("concat_varying", "hidden")
            )
            found = two_sample_ci(
                concat[:, None],
                hidden[:, None],
                metrics.difference_of_means,
                reps=spec.bootstrap_reps,
                seed=spec.seed,
            )
            decisions.append(_decide(found))
            text.append(f"concat − hidden on extrapolation contexts = {found}")
        return Verdict(_all(decisions), "; ".join(text) + " (95% CI over seeds; above 0 holds)")

    return Check(rule, decide)


def _tabular(runs: Mapping[str, RunDir], gain: float) -> Verdict:
    (run,) = runs.values()
    results = run.results()
    gaps = (results["optimal_return"] - results["oblivious_return"]).groupby(results["trial"])
    gap = gaps.mean()
    paper = float(gap["paper 3-state cMDP"])
    return Verdict(
        paper > 1e-9,
        f"exact gap of the best deterministic context-oblivious policy on the paper's 3-state "
        f"cMDP: {paper:.4g}; {int((gap > 1e-9).sum())} of {len(gap)} cMDPs solved have a gap above 0",
    )


tabular_check = Check(
    "holds when the exact optimality gap of the best deterministic context-oblivious policy on the "
    "paper's 3-state cMDP is above 0 (solved exactly: no sampling, no interval).",
    _tabular,
    gated=False,
)


@dataclasses.dataclass(frozen=True)
class PaperFigure:
    """A figure of the paper: its spec file(s), the check of its claim and its small budget."""

    name: str
    check: Check
    small: Mapping[str, Any]  # spec fields for two CPU cores (agent_options merge into the spec's)
    parts: tuple[str, ...] = ()  # spec files (stems) of a figure of several runs

    def files(self) -> dict[str, Path]:
        stems = self.parts or (self.name,)
        return {
            stem.removeprefix(self.name + "_") or stem: SPEC_FOLDER / f"{stem}.yaml"
            for stem in stems
        }

    def header(self, key: str, part: str | None = None) -> str:
        """The ``# Key:`` header of the figure's first spec (or of ``part``), with its
        continuation lines (``# `` lines up to the next key) joined."""
        path = self.files()[part] if part else next(iter(self.files().values()))
        found, inside = [], False
        for line in path.read_text(encoding="utf-8").splitlines():
            if not line.startswith("#"):
                break
            body = line[1:].strip()
            starts = re.match(r"[A-Z][a-z]+:", body)
            if starts:
                inside = body.startswith(f"{key}:")
                body = body[len(key) + 1 :].strip() if inside else body
            if inside:
                found.append(body)
        return " ".join(found)

    @property
    def rule(self) -> str:
        """The decision rule, as the spec's ``# Decision:`` line and the page state it."""
        return self.check.rule + (f" {GATE}" if self.check.gated else "")

    @property
    def stated_budget(self) -> bool:
        """Whether the paper states the budget its ``paper`` scale runs (else: a full budget)."""
        return self.header("Budget").startswith("the paper's")


def _smallest_budget(spec, options: dict) -> int:
    """The smallest power-of-two step budget (from 256) the agent accepts for every variant."""
    budget = 256
    while True:
        try:
            for variant in spec.variants:
                spec.agent_entry().config(spec.env, {**options, "total_timesteps": budget}, variant)
            return budget
        except ConfigError:
            if budget >= 1 << 20:
                raise
            budget *= 2


def _tiny(data: dict) -> dict:
    """A smoke-test budget: every protocol step runs once, in seconds to a minute; decides nothing."""
    spec = parse_spec(data)
    out = copy.deepcopy(data)
    fields = {f.name for f in dataclasses.fields(spec)}
    small = {
        "seeds": 2, "eval_episodes": 1, "max_steps": 20, "num_contexts": 2, "batch_size": 4,
        "num_train_contexts": 4, "num_test_contexts": 4, "population": 2, "rounds": 1,
        "num_random": 1, "magnitudes": [0.5, 1.0], "bootstrap_reps": 50,
    }  # fmt: skip
    out.update({k: v for k, v in small.items() if k in fields and k not in spec.unused_fields})
    if spec.protocol == "sensitivity":
        out["features"] = list(spec.feature_names()[:2])
    if spec.trains_agents:
        names = spec.agent_entry().option_names()
        options = {
            "learning_starts": 32, "num_envs": 2, "num_steps": 16, "batch_size": 16,
            "log_every": 64, "hidden_sizes": [16, 16],
        }  # fmt: skip
        merged = {
            **out.get("agent_options", {}),
            **{k: v for k, v in options.items() if k in names},
        }
        budget = _smallest_budget(spec, merged)
        if spec.protocol == "hpo":  # a member trains steps_per_round steps a round
            out["steps_per_round"] = budget
        else:
            merged["total_timesteps"] = budget
        out["agent_options"] = merged
    return out


def spec_data(figure: PaperFigure, part: str, scale: str) -> dict:
    """The spec of one part of ``figure`` at ``scale`` (paper: the file as it ships)."""
    if scale not in SCALES:
        raise SpecError(f"scale: unknown scale {scale!r}; choose one of {list(SCALES)}")
    path = figure.files()[part]
    data = load_yaml(path.read_text(encoding="utf-8"), str(path))
    if scale == "small":
        for key, value in figure.small.items():
            data[key] = {**data.get(key, {}), **value} if key == "agent_options" else value
    elif scale == "tiny":
        data = _tiny(data)
    data["name"] = f"{data['name']}-{scale}"
    return data


def _steps(spec) -> int:
    return spec.training_steps(_plan(spec).trials)


def _plan(spec):
    """``expand(spec)``, once per spec: expanding draws the contexts, and the page reads every
    figure's specs several times (budgets, estimates, checks)."""
    return _plan_of(yaml.safe_dump(spec_to_dict(spec), sort_keys=True))


@functools.cache
def _plan_of(text: str):
    return expand(parse_spec(yaml.safe_load(text)))


@functools.cache
def _spec_of(text: str):
    """A run's spec.yaml parsed once: every estimate on the page reads every run's spec."""
    return parse_spec(load_yaml(text))


def figure_folder(root: str | Path, name: str, scale: str) -> Path:
    return Path(root) / f"{name}-{scale}"


def finished_runs(figure: PaperFigure, root: str | Path, scale: str) -> dict[str, RunDir] | None:
    """The figure's runs at ``scale`` under ``root`` when every part has all its results."""
    runs = {}
    for part in figure.files():
        run = RunDir(figure_folder(root, figure.name, scale) / part)
        if not (run.path / "spec.yaml").exists():
            return None
        plan = _plan(run.spec())
        if run.results().empty or len(run.finished()) < max(len(plan.chunks), 1):
            return None
        runs[part] = run
    return runs


def wall_seconds(run: RunDir) -> float:
    """Seconds ``contextrl paper run`` spent on the run (else its chunks' summed seconds)."""
    return float(run.manifest().get("paper_wall_seconds", sum(run.timings().values())))


def machine() -> str:
    """What trained, for the wall times the page states: JAX's accelerator, else the CPU cores."""
    device = jax.devices()[0]
    cores = f"{os.cpu_count()} CPU cores"
    return cores if device.platform == "cpu" else f"one {device.device_kind} and {cores}"


def run_figure(
    name: str,
    scale: str = "small",
    *,
    root: str | Path = PAPER_RUNS,
    executor: str = "local",
    address: str | None = None,
    batch_size: int | None = None,
    progress: bool = True,
) -> tuple[Verdict, Path]:
    """Run (or finish) every part of a figure at ``scale``, then write the figure's report
    (``paper.html``: the claim, the verdict and the parts' figures); returns the verdict and it.
    ``batch_size`` sets how many trials a new part trains in one vmapped call (a GPU takes all)."""
    figure = FIGURES[name]
    folder = figure_folder(root, name, scale)
    for part in figure.files():
        path = folder / part
        start = time.perf_counter()
        if (path / "spec.yaml").exists():  # finish it as its own spec.yaml says
            run, _ = resume(path, executor=executor, address=address, progress=progress)
        else:
            data = spec_data(figure, part, scale)
            if batch_size is not None:
                data["batch_size"] = batch_size
            run, _ = run_experiment(
                data, out=path, executor=executor, address=address, progress=progress
            )
        spent = time.perf_counter() - start
        run.update_manifest(
            paper_wall_seconds=run.manifest().get("paper_wall_seconds", 0.0) + spent,
            paper_machine=machine(),
        )
    runs = finished_runs(figure, root, scale)
    if runs is None:
        raise RuntimeError(f"{name}: some chunks failed; rerun the same command to retry them")
    verdict = figure.check(runs)
    return verdict, write_text(folder / "paper.html", _figure_report(figure, scale, runs, verdict))


def _figure_report(figure: PaperFigure, scale: str, runs: Mapping[str, RunDir], verdict) -> str:
    text = [
        f"The paper ({figure.header('Paper')}): {figure.header('Claim')}",
        f"Decision rule: {figure.rule}",
        f"Here, at the {scale} budget: the claim {verdict.word}"
        + (f" ({verdict.withheld})" if verdict.withheld else "")
        + f". {verdict.evidence}.",
    ]
    rows = [
        {
            "part": part,
            "training steps": f"{_steps(run.spec()):,}",
            "time": duration(wall_seconds(run)),
            "report": str(Path(part) / "report.html"),
        }
        for part, run in runs.items()
    ]
    figures = [
        ReportFigure(f"{part}-{png.stem}", png.read_bytes(), f"{part}: {png.stem}")
        for part, run in runs.items()
        for png in sorted((run.path / "figures").glob("*.png"))
    ]
    sections = [Section("The paper's claim and ours", text, [("Runs", rows)], figures)]
    return render(f"contextrl paper: {figure.name} ({scale})", sections, {"scale": scale})


def _machines(runs) -> str:
    """Where ``runs`` trained, as their manifests say: the machine and JAX's version."""
    manifests = [run.manifest() for run in runs]
    named = {f"{m['paper_machine']} (JAX {m['versions']['jax']})" for m in manifests}
    return " and ".join(sorted(named))


def estimate(figure: PaperFigure, scale: str, root: str | Path) -> str:
    """Wall time of ``figure`` at ``scale`` and where: measured when it ran under ``root``, else
    extrapolated from the seconds per training step of finished runs with the same environment and
    agent (those at ``scale``, else at the small scale), else "not measured"."""
    runs = finished_runs(figure, root, scale)
    if runs is not None:
        return (
            f"{duration(sum(wall_seconds(r) for r in runs.values()))} on {_machines(runs.values())}"
        )
    steps, keys = 0, set()
    for part in figure.files():
        spec = parse_spec(spec_data(figure, part, scale))
        steps += _steps(spec)
        keys.add((spec.env, spec.agent))
    for measured_scale in dict.fromkeys((scale, "small")):
        seconds = measured_steps = 0.0
        measured = []
        for spec_file in sorted(Path(root).glob(f"*-{measured_scale}/*/spec.yaml")):
            run = RunDir(spec_file.parent)
            spec = _spec_of(spec_file.read_text(encoding="utf-8"))
            finished = "paper_machine" in run.manifest()  # its `contextrl paper run` ended
            if (spec.env, spec.agent) in keys and finished and _steps(spec):
                seconds += wall_seconds(run)
                measured_steps += _steps(spec)
                measured.append(run)
        if measured_steps and steps:
            return f"≈ {duration(steps * seconds / measured_steps)} on {_machines(measured)}"
    return "not measured"


def figure_rows(root: str | Path) -> list[dict[str, str]]:
    """A row per figure: what ``contextrl paper`` lists."""
    rows = []
    for figure in FIGURES.values():
        steps = {
            scale: sum(_steps(parse_spec(spec_data(figure, p, scale))) for p in figure.files())
            for scale in ("paper", "small")
        }
        rows.append(
            {
                "figure": figure.name,
                "paper": figure.header("Paper").split(":")[0],
                "claim": figure.header("Claim"),
                "steps (paper)": f"{steps['paper']:,}",
                "time (paper)": estimate(figure, "paper", root),
                "steps (small)": f"{steps['small']:,}",
                "time (small)": estimate(figure, "small", root),
            }
        )
    return rows


def results_page(root: str | Path) -> str:
    """``docs/paper.md``: every figure with its claim, its decision rule and its deviations from the
    paper, and, per scale run under ``root``, our statistic, the budget, the time it took and the
    verdict: verdicts at the full budget apart from the evidence of smaller runs."""
    lines = [
        "# The paper, reproduced",
        "",
        "Every figure of the paper with an experiment behind it, its claim, the rule that decides "
        "it and what the library measured. Generated by `contextrl paper page` from the run "
        "folders of `contextrl paper run` "
        f"(here `{root}`: specs, manifests, results, curves and timings; `contextrl report RUN` "
        "draws a run's figures); a figure not run says so. The specs are in `examples/paper/` "
        "(shipped as `contextrl/paper/`), each stating the paper's section, the claim, its decision "
        "rule and where its settings differ from the paper's.",
        "",
        "**How claims are decided.** Each rule was written before the runs. *holds* / *does not "
        "hold*: the 95% intervals decide as the rule says; *undecided*: they do not at that "
        f"budget; *no verdict*: the run cannot decide the claim. {GATE} Intervals resample the "
        "unit that was replicated independently: seeds, each with all its test contexts, where "
        "one agent per seed was tested on many contexts; contexts too where they were drawn from "
        "the distribution the claim is about; each context's specialists where every context has "
        "its own agents (the experiments page's statistics section says which design each "
        "protocol has).",
        "",
        "**Budgets.** *The paper's budget* only where the paper states it; elsewhere the `paper` "
        "scale runs a *full budget* chosen here (each figure says why). `--scale small` runs the "
        "budget two CPU cores afford: its runs have fewer seeds and steps, so they are evidence at "
        "a smaller budget, never a verdict. Each figure states the time its full budget takes "
        "(measured, or extrapolated per training step from runs of the same environment and "
        "agent); on a Ray cluster it is `contextrl paper run FIGURE --scale paper --executor ray "
        "--address auto`. The paper's Figure 1 (CARLFetch at three target distances and three "
        "ground frictions) is a picture, not an experiment: `contextrl render Fetch --grid "
        "target_distance=2,6,10 --grid friction=0.05,0.6,1.0` draws it (families/brax.md).",
        "",
    ]
    for figure in FIGURES.values():
        full = "the paper's budget" if figure.stated_budget else "full budget"
        scales = "; ".join(
            f"{_label(figure, scale)}: {_budgets(figure, scale)}" for scale in ("paper", "small")
        )
        lines += [
            f"## {figure.name}",
            "",
            f"**Paper**: {figure.header('Paper')}  ",
            f"**Claim**: {figure.header('Claim')}  ",
            f"**Decision rule**: {figure.rule}  ",
            f"**Settings and deviations from the paper**: {_settings(figure)}  ",
            f"**Budget**: {figure.header('Budget')}  ",
            f"**Agents and test contexts**: {scales}  ",
            f"**Run**: `contextrl paper run {figure.name} --scale small` ({full}: `--scale paper`)",
            "",
        ]
        ran = False
        for scale in SCALES:
            runs = finished_runs(figure, root, scale)
            if runs is None:
                continue
            ran = True
            verdict = figure.check(runs)
            seconds = sum(wall_seconds(r) for r in runs.values())
            where = (
                f"{_budgets(figure, scale, runs)}; {duration(seconds)} on "
                f"{_machines(runs.values())}"
            )
            withheld = f" ({verdict.withheld})" if verdict.withheld else ""
            if not figure.check.gated:  # solved exactly: every scale decides
                lines.append(
                    f"- **Solved exactly** ({where}): the claim **{verdict.word}**. "
                    f"{verdict.evidence}."
                )
            elif scale == "paper":
                lines.append(
                    f"- **At {full}** ({where}): the claim **{verdict.word}**{withheld}. "
                    f"{verdict.evidence}."
                )
            else:
                lines.append(
                    f"- **Evidence at a smaller budget ({scale})** ({where}): no verdict at this "
                    f"budget{withheld}; its intervals alone would say *{_rule_word(verdict)}*. "
                    f"{verdict.evidence}."
                )
        if not ran:
            lines.append(
                f"- Not run yet. Estimated time at the small budget: "
                f"{estimate(figure, 'small', root)}."
            )
        trains = any(
            parse_spec(spec_data(figure, p, "paper")).trains_agents for p in figure.files()
        )
        if trains and finished_runs(figure, root, "paper") is None:
            lines.append(f"- **At {full}**: not run; {estimate(figure, 'paper', root)}.")
        lines.append("")
    lines += NOT_COVERED
    return "\n".join(lines)


def _rule_word(verdict: Verdict) -> str:
    """What the rule's intervals say, whether or not a verdict may be drawn from them."""
    return {True: "holds", False: "does not hold", None: "undecided"}[verdict.holds]


def _settings(figure: PaperFigure) -> str:
    """The settings of each part (one line for a figure of one spec)."""
    parts = figure.files()
    if len(parts) == 1:
        return figure.header("Settings")
    return " ".join(f"*{part}*: {figure.header('Settings', part)}" for part in parts)


def _label(figure: PaperFigure, scale: str) -> str:
    if scale == "paper":
        return "the paper's" if figure.stated_budget else "full"
    return scale


NOT_COVERED = [
    "## What of the paper is not covered",
    "",
    "- §5.1's feature counts per environment and the radar figure of the benchmark's properties: "
    "a table and a drawing about the library, not experiments (the environment pages list every "
    "feature with its bounds and what it acts on).",
    "- §6.1's sentences on the shape of the curves (max_speed hard below A = 0.7, then abruptly "
    "easy; l hard at both ends): the figures show them (`contextrl report RUN`); no rule decides "
    "them.",
    "- §6.3's training-curve claims (on DmcWalker the visible agent learns faster, is more stable "
    "and reaches a higher final return) and its counts of test failures: only the mean test "
    "return is decided; each run's report draws the training curves.",
    "- §6.3's remark that the concat agents do better on some unseen Pendulum contexts and the "
    "hidden agent on a slice of them: the per-context returns are in each run's report, not "
    "decided.",
    "- §6.4's heat-map details (large update intervals with extreme pole lengths hardest; the "
    "concat agent's advantage most pronounced on mode C): drawn; only the sentences named in "
    "kirk_cartpole's rule are decided.",
    "- That the Pendulum optimality gap is smaller than CartPole's (§6.2): the two figures are "
    "decided apart; returns on different scales are not compared.",
    "- Appendix E's figures of environments without a spec here, and appendix H's challenges (no "
    "experiments).",
    "",
]


def _budgets(figure: PaperFigure, scale: str, runs: Mapping[str, RunDir] | None = None) -> str:
    """Each part's budget at ``scale`` (read from its run where it ran)."""
    specs = {
        part: runs[part].spec() if runs else parse_spec(spec_data(figure, part, scale))
        for part in figure.files()
    }
    if len(specs) == 1:
        return _budget(next(iter(specs.values())))
    return "; ".join(f"{part}: {_budget(spec)}" for part, spec in specs.items())


def _budget(spec) -> str:
    """Agents × steps each (and the total), seeds, and the test contexts of one spec."""
    if not spec.trains_agents:
        return "exact solution"
    trials = _plan(spec).trials
    per_agent = {spec.training_steps([t]) for t in trials}
    each = f"{per_agent.pop():,} steps each" if len(per_agent) == 1 else "steps differ"
    parts = [f"{len(trials)} agents × {each} ({_steps(spec):,} in all)", f"seeds {spec.seeds}"]
    for field in ("num_contexts", "num_train_contexts", "population", "rounds"):
        if hasattr(spec, field) and field not in spec.unused_fields:
            parts.append(f"{field.replace('num_', '').replace('_', ' ')} {getattr(spec, field)}")
    parts.append(f"test contexts: {_test_contexts(spec)}")
    return ", ".join(parts)


def _test_contexts(spec) -> str:
    """How many contexts each agent is tested on, and whether they are a draw or a fixed set."""
    plan = _plan(spec)
    sizes = sorted({len(plan.sets[t.test_set]) for t in plan.trials})
    kind = "drawn from the distribution" if spec.test_contexts == SAMPLED else "a fixed set"
    return f"{' or '.join(str(n) for n in sizes)} per agent ({kind})"


_SMALL_C51 = {"agent_options": {"total_timesteps": 30000}}
_SMALL_SAC = {"agent_options": {"total_timesteps": 20000}}
FIGURES = {
    f.name: f
    for f in [
        PaperFigure("tabular_cmdp", tabular_check, {}),
        PaperFigure(
            "ecdf_pendulum",
            sensitivity_check(
                harmless=("initial_angle_max", "initial_velocity_max"),
                brittle=("max_speed", "dt", "g", "l"),
            ),
            {"seeds": 3, "eval_episodes": 5},
        ),
        PaperFigure(
            "optgap_cartpole",
            gap_check(30.0, finished=True),
            {**_SMALL_C51, "num_contexts": 8, "seeds": 3, "batch_size": 9},
        ),
        PaperFigure(
            "optgap_pendulum", gap_check(0.0), {"num_contexts": 8, "seeds": 3, "batch_size": 9}
        ),
        PaperFigure(
            "visibility_dmcwalker",
            better_check("concat_varying", "hidden"),
            {
                "agent_options": {"total_timesteps": 60000},
                "seeds": 2,
                "max_steps": 200,
                "num_test_contexts": 20,
            },
        ),
        PaperFigure(
            "visibility_pendulum",
            similar_check("concat_varying", "hidden"),
            {"seeds": 5, "num_test_contexts": 50, "eval_episodes": 5},
        ),
        *(
            PaperFigure(
                name,
                check,
                {
                    **small,
                    "seeds": 3,
                    "num_train_contexts": 200,
                    "num_test_contexts": 225,
                    "eval_episodes": 2,
                },
            )  # fmt: skip
            for name, check, small in (
                ("kirk_cartpole", kirk_check(concat_extrapolates=True), _SMALL_C51),
                ("kirk_pendulum_gravity_dt", kirk_check(), _SMALL_SAC),
                ("kirk_pendulum_gravity_length", better_check("hidden", "concat_varying"), {}),
            )
        ),
        *(
            figure
            for env, small in (
                ("pendulum", {}),
                ("mountaincar", _SMALL_C51),
                ("cartpole", _SMALL_C51),
                ("acrobot", _SMALL_C51),
                ("lunarlander", _SMALL_C51),
            )
            for figure in (
                PaperFigure(
                    f"baseline_{env}_default",
                    sensitivity_check(),
                    {**small, "seeds": 3, "eval_episodes": 5},
                ),
                PaperFigure(
                    f"baseline_{env}_visibility",
                    better_check("concat_varying", "hidden"),
                    {**small, "seeds": 3, "num_train_contexts": 32, "num_test_contexts": 32},
                ),
            )
        ),
        *(
            PaperFigure(
                f"ecdf_{env}",
                sensitivity_check(),
                {"agent_options": {"total_timesteps": 20000}, "seeds": 2, "eval_episodes": 2},
            )
            for env in ("bipedalwalker", "dmcfish", "dmcquadruped", "dmcwalker")
        ),
        *(
            PaperFigure(
                f"pb2_{env}",
                better_check("hidden", "concat_all"),
                {"population": 4, "rounds": 4, "steps_per_round": 10000},
                parts=(f"pb2_{env}_hidden", f"pb2_{env}_visible"),
            )
            for env in ("acrobot", "lunarlander", "pendulum")
        ),
        PaperFigure(
            "platformer_conditioning",
            better_check("concat_varying", "hidden"),
            {"agent_options": {"total_timesteps": 500000}, "seeds": 3},
        ),
    ]
}
