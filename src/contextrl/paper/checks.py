"""The decision rules of the paper's claims, fixed before any run: each :class:`Check` states its rule
and decides it from a figure's finished runs with the intervals of :mod:`contextrl.analysis.scores`,
or gives no verdict, saying why (too few seeds, or agents that did not beat a random policy)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping

import numpy as np
import pandas as pd

from contextrl.analysis import metrics
from contextrl.analysis.intervals import SEEDS, Interval, bootstrap_ci, two_sample_ci
from contextrl.analysis.scores import (
    LEARNED_MARGIN,
    design_words,
    gap_statistics,
    learned,
    magnitude_lines,
    per_seed_means,
    score_matrices,
    worst_drop,
)
from contextrl.experiments.protocols.train_test import REGIONS
from contextrl.experiments.reports import run_cells
from contextrl.experiments.runs import RunDir
from contextrl.paper.plans import outlined, planned

# The decision rules, fixed before any run. A verdict needs this many seeds (the unit of replication)
MIN_SEEDS = 5
# "No difference" is reproduced inside ± this fraction of the agents' gain over a random policy at
# their training contexts; a "better" claim is not reproduced when the difference stays below it.
EQUIVALENCE = 0.10
# A feature is harmless when its drop stays below HARMLESS × the gain, brittle above BRITTLE ×.
HARMLESS, BRITTLE = 0.10, 0.50
# These margins are the library's, not the paper's: a verdict is also drawn at these multiples of
# them, and one that changes across them is undecided.
MARGIN_SCALES = (0.5, 1.0, 2.0)
MARGIN_RULE = (
    "The margin is the library's, not the paper's: the verdict is also drawn at half and at twice "
    "it, and one that changes across that range is undecided."
)
WORDS = {True: "reproduced", False: "not reproduced", None: "undecided"}
GATE = (
    f"No verdict from fewer than {MIN_SEEDS} seeds, or where an agent does not beat a random policy "
    f"at its training contexts by {LEARNED_MARGIN:.0%} of max(|random return|, 1)."
)


@dataclasses.dataclass(frozen=True)
class Verdict:
    """Whether the paper's claim was reproduced at the budget it ran at (``holds``; None: the
    intervals do not decide it), or, where ``withheld`` says why, no verdict at all: the evidence
    and what its intervals alone would say are then shown, not judged. ``gate_only``: withheld by
    the learnability gate on runs under way, before any interval was computed (``holds`` says
    nothing then).

    ``margins``: where the rule's margin is the library's, the verdicts at half, at and at twice it
    (``holds`` is undecided where they differ), so a reader sees how much the margin decides.
    ``at`` and ``cause``: for a claim not reproduced, the budget and settings it was not reproduced
    at, and the most likely cause the runs show (see :meth:`PaperFigure.verdict`)."""

    holds: bool | None
    evidence: str
    withheld: str = ""
    gate_only: bool = False
    margins: tuple[bool | None, ...] = ()
    at: str = ""
    cause: str = ""

    @property
    def word(self) -> str:
        return "no verdict" if self.withheld else WORDS[self.holds]

    def sentence(self, emphasis: str = "") -> str:
        """The verdict as words: "reproduced", "not reproduced at … (most likely cause: …)", or
        "no verdict on the claim (why)", with the margins' verdicts where the margin is the
        library's; ``emphasis`` wraps the verdict (``**`` on the page)."""
        if self.withheld:
            return f"{emphasis}no verdict{emphasis} on the claim ({self.withheld})"
        text = f"{emphasis}{self.word}{emphasis}"
        if self.holds is False and self.at:
            text += f" at {self.at} (most likely cause: {self.cause})"
        return text + self.margin_words(emphasis[:1])

    def margin_words(self, emphasis: str = "") -> str:
        """What the verdict is at half, at and at twice the library's margin ("" where the margin
        is the paper's or the rule has none); ``emphasis`` wraps each verdict."""
        if not self.margins:
            return ""
        said = ", ".join(
            f"{emphasis}{WORDS[found]}{emphasis} at {where}"
            for where, found in zip(("half of it", "it", "twice it"), self.margins, strict=True)
        )
        flips = len(set(self.margins)) > 1
        return f" (the margin is the library's: {said}" + (
            "; undecided, as the verdict changes across them)" if flips else ")"
        )


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
    return _learning(pd.concat(frames, ignore_index=True) if frames else pd.DataFrame())


def _learning(frame: pd.DataFrame) -> Learning:
    """:func:`learning` of one training table (a run's, or only the agents whose seeds are done)."""
    if frame.empty:
        return Learning({})
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
    and the seed floor apply (every figure that trains agents). ``settle(runs, gain)``, where the
    rule has one: on runs under way, the verdict no unfinished chunk can change, or None."""

    rule: str
    decide: Callable[[Mapping[str, RunDir], float], Verdict]
    gated: bool = True
    settle: Callable[[Mapping[str, RunDir], float], Verdict | None] | None = None

    def __call__(self, runs: Mapping[str, RunDir]) -> Verdict:
        """The verdict, or no verdict with the reason, always with the evidence and, for agents
        that train, their trained and random returns."""
        return self._judged(runs, self.decide)

    def settled(self, runs: Mapping[str, RunDir]) -> Verdict | None:
        """On runs under way: the verdict their finished chunks already fix, gated as a finished
        run's; else, for a gated check, no verdict once an agent with every seed trained has not
        beaten a random policy (its mean over them is final); else None."""
        found = self._judged(runs, self.settle) if self.settle is not None else None
        if found is None and self.gated:
            return _unlearned_and_complete(runs)
        return found

    def _judged(self, runs: Mapping[str, RunDir], decide) -> Verdict | None:
        if not self.gated:
            return decide(runs, np.nan)
        learned_ = learning(runs)
        found = decide(runs, learned_.gain if learned_.returns else np.nan)
        if found is None:
            return None
        spec = next(iter(runs.values())).spec()
        if not spec.agent_entry().trained:
            return dataclasses.replace(found, withheld=f"the {spec.agent} agent does not learn")
        evidence = f"{found.evidence}; {learned_}"
        reasons = []
        seeds = _seeds(runs)
        if seeds < MIN_SEEDS:
            reasons.append(f"{seeds} seeds, fewer than {MIN_SEEDS}")
        failed = learned_.failed()
        if not learned_.returns or failed:
            which = ", ".join(failed) or "no agent has a training record"
            reasons.append(f"the agent did not learn at this budget: {which}")
        return dataclasses.replace(found, evidence=evidence, withheld="; ".join(reasons))


def _unlearned_and_complete(runs: Mapping[str, RunDir]) -> Verdict | None:
    """No verdict, whatever the unfinished chunks give, when the agents of a variant and kind whose
    chunks have all finished did not beat a random policy at their training contexts; else None.
    The intervals are not computed (the variants to come are missing): a ``gate_only`` verdict."""
    waiting, frames = set(), []
    for run in runs.values():
        spec = run.spec()
        if not spec.agent_entry().trained:
            return None
        plan, finished = outlined(spec), run.finished()
        for c, chunk in enumerate(plan.chunks):
            if c not in finished:
                waiting |= {(plan.trials[i].variant, plan.trials[i].kind) for i in chunk}
        frames.append(run.training())
    frame = pd.concat(frames, ignore_index=True)
    if not waiting or frame.empty:
        return None  # finished (the check itself says) or nothing trained yet
    pairs = pd.MultiIndex.from_frame(frame[["variant", "kind"]])
    complete = frame[~pairs.isin(list(waiting))]
    learned_ = _learning(complete)
    failed = learned_.failed()
    if not failed:
        return None
    seeds = sorted(set(complete.groupby(["variant", "kind"])["seed"].nunique()))
    return Verdict(
        None,
        f"{learned_}, over {' or '.join(map(str, seeds))} seeds each, all trained (the "
        "unfinished chunks train other agents)",
        f"the agent did not learn at this budget: {', '.join(failed)}",
        gate_only=True,
    )


def _over_margins(judge: Callable[[float], bool | None], evidence: str) -> Verdict:
    """The verdict of ``judge(scale)`` (the rule with its library-chosen margin times ``scale``) at
    each of MARGIN_SCALES: the one at the margin itself where all agree, else undecided."""
    found = tuple(judge(scale) for scale in MARGIN_SCALES)
    holds = found[MARGIN_SCALES.index(1.0)] if len(set(found)) == 1 else None
    return Verdict(holds, evidence, margins=found)


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
    """The run's score cells; its contexts are drawn only where a trial has no results (its cells
    are named by its test contexts)."""
    spec, results = run.spec(), run.results()
    plan = outlined(spec)
    if {t.id for t in plan.trials} - (set(results["trial"]) if len(results) else set()):
        plan = planned(spec)
    return spec, run_cells(run, plan, results)


def gap_check(at_least: float, finished: bool = False, most_per_step: float | None = None) -> Check:
    """Specialists beat the general agent by more than ``at_least`` in mean, median and IQM (and,
    where ``finished``, reach the best return in more cells: the paper's finished episodes).

    ``most_per_step``: the largest reward a step can give (CartPole's 1), so an episode returns at
    most that times its step limit. Then a run under way is settled once its general agents are
    trained: the specialists not yet trained, each put at that most in every test episode, give
    intervals no finished run can exceed (every replicate of the bootstrap draws the same seeds and
    contexts whatever the returns, and mean, median and IQM never fall when a return rises), so an
    interval of them below ``at_least`` already says the claim is not reproduced. Such a verdict
    names the general agent at that most as its cause where its IQM test return is within 1 % of
    it."""
    parts = "mean, median and IQM" + (" and the fraction of finished episodes" if finished else "")
    rule = (
        "reproduced when the 95% intervals of the specialists' minus the general agent's mean, "
        f"median and IQM test return all lie above {at_least:g}"
        + (
            " and that of the fraction of finished episodes (cells at the best return) above 0"
            if finished
            else ""
        )
        + "; not reproduced when one of them lies below; undecided otherwise. Intervals resample "
        "the general agent's seeds (each with all its contexts) and the contexts, each with its "
        f"specialists ({parts})."
    )

    def statistics(cells: pd.DataFrame, spec):
        return gap_statistics(cells, spec.variants, **spec.design)[spec.variants[0]]

    def at_ceiling(stats, spec) -> str:
        """The general agent at the return ceiling, where it is: no room left to beat it."""
        if most_per_step is None:
            return ""
        most = most_per_step * spec.make_env().max_steps
        iqm = metrics.aggregate_iqm(stats.general.matrix)
        if iqm < 0.99 * most:
            return ""
        return (
            f"the general agent at the return ceiling (its IQM test return {iqm:.4g} of at most "
            f"{most:g}), which leaves the specialists no room to beat it by {at_least:g}"
        )

    def decide(runs: Mapping[str, RunDir], gain: float) -> Verdict:
        (run,) = runs.values()
        spec, cells = _cells(run)
        stats = statistics(cells, spec)
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
            here = (
                f"here {1 - done['general'] / done['specialists']:.0%}"
                if done["specialists"]
                else "here the specialists finished none"
            )
            text += (
                f"finished episodes (return ≥ {done['threshold']:.4g}): general "
                f"{done['general']:.2f}, specialists {done['specialists']:.2f}, difference "
                f"{done['difference']} (needs to lie above 0; the paper: about 40% fewer for the "
                f"general agent, {here}); "
            )
        text += (
            f"P(specialist > general) = {stats.improvement}; mean return per seed: general "
            f"{_numbers(seeds['general'])}, specialists {_numbers(seeds['specialists'])}"
        )
        return Verdict(_all(decisions), text, cause=at_ceiling(stats, spec))

    def settle(runs: Mapping[str, RunDir], gain: float) -> Verdict | None:
        (run,) = runs.values()
        spec = run.spec()
        plan, finished = planned(spec), run.finished()
        cells = run_cells(run, plan, run.results())
        waiting = {
            plan.trials[i].id
            for c, chunk in enumerate(plan.chunks)
            if c not in finished
            for i in chunk
        }
        absent = cells["return"].isna()
        untrained = cells["trial"].isin(waiting) & (cells["kind"] == "specialist")
        if not absent.any() or (absent & ~untrained).any():
            return None  # finished (``decide`` says), a general agent to come, or a failed cell
        most = most_per_step * spec.make_env().max_steps
        stats = statistics(cells.assign(**{"return": cells["return"].where(~absent, most)}), spec)
        below = [name for name, d in stats.differences.items() if d.high < at_least]
        if not below:
            return None
        verb = "lies" if len(below) == 1 else "lie"
        return Verdict(
            False,
            f"even if each of the {int(absent.sum())} specialists not yet trained returned "
            f"{most:g} (the most an episode can) in every test episode, specialists − general "
            "would be: "
            + ", ".join(f"{name} {d}" for name, d in stats.differences.items())
            + f" (95% CI), so {' and '.join(below)} {verb} below {at_least:g} whatever they return",
            cause=at_ceiling(stats, spec),
        )

    return Check(rule, decide, settle=settle if most_per_step is not None else None)


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
    a: str,
    b: str,
    rule: str,
    decide: Callable[[Interval, float], bool | None],
    bounds: str,
    most_per_step: float | None = None,
) -> Check:
    """A claim about mean test return ``a`` − ``b``: ``decide(interval, margin)`` says whether it
    is reproduced, the margin being EQUIVALENCE × the agents' gain (and half and twice that, the
    margin being the library's); ``bounds`` (formatted with ``margin`` and ``gain``) says where the
    evidence stands against it. ``most_per_step``: the largest reward a step can give, so an
    episode returns at most that × the time limit; where ``b`` is closer to it than the margin,
    ``a`` has no room to beat it by the margin, and a claim not reproduced names that cause."""

    def check(runs: Mapping[str, RunDir], gain: float) -> Verdict:
        scores, diff, over = _variant_difference(runs, a, b)
        margin = EQUIVALENCE * gain
        found = _over_margins(
            lambda scale: decide(diff, scale * margin),
            f"mean test return {a} − {b} = {diff} (95% CI over {over}; "
            + bounds.format(margin=margin, gain=gain)
            + "); "
            + _means(scores, a, b),
        )
        if most_per_step is None:
            return found
        most = most_per_step * next(iter(runs.values())).spec().make_env().max_steps
        base = metrics.aggregate_mean(scores[b].matrix)
        if most - base >= margin:
            return found
        cause = (
            f"{b} at the return ceiling (its mean test return {base:.4g} of at most {most:g} "
            f"leaves {a} less room than the margin {margin:.4g} to beat it by)"
        )
        return dataclasses.replace(found, cause=cause)

    return Check(f"{rule} {MARGIN_RULE}", check)


def better_check(a: str, b: str, most_per_step: float | None = None) -> Check:
    """Variant ``a``'s mean test return is above ``b``'s; not better by a meaningful amount when
    the interval lies below the equivalence margin (``most_per_step``: see
    :func:`_difference_check`)."""

    def decide(diff: Interval, margin: float) -> bool | None:
        return True if diff.low > 0 else (False if diff.high < margin else None)

    rule = (
        f"reproduced when the 95% interval of mean test return {a} − {b} lies above 0; not "
        f"reproduced when it lies below {EQUIVALENCE:.0%} of the agents' gain over a random policy "
        "at their training contexts (not better by a meaningful amount); undecided otherwise."
    )
    bounds = "reproduced above 0, not reproduced below {margin:.4g}"
    return _difference_check(a, b, rule, decide, bounds, most_per_step)


def similar_check(a: str, b: str) -> Check:
    """No meaningful difference between the mean test returns of ``a`` and ``b``: equivalence
    within a margin fixed before the run, so more seeds can only sharpen the verdict."""

    def decide(diff: Interval, margin: float) -> bool | None:
        if -margin < diff.low and diff.high < margin:
            return True
        return False if diff.low > margin or diff.high < -margin else None

    rule = (
        f"reproduced when the 95% interval of mean test return {a} − {b} lies inside ± "
        f"{EQUIVALENCE:.0%} of the agents' gain over a random policy at their training contexts; "
        "not reproduced when it lies outside that margin; undecided otherwise."
    )
    bounds = f"the margin ± {{margin:.4g}} = {EQUIVALENCE:.0%} of the gain {{gain:.4g}}"
    return _difference_check(a, b, rule, decide, bounds)


def _zone(drop: Interval, gain: float, scale: float = 1.0) -> str | None:
    """harmless, moderate or brittle where the drop's interval lies in one zone, else None (the
    zones' bounds times ``scale``)."""
    harmless, brittle = scale * HARMLESS * gain, scale * BRITTLE * gain
    if drop.high < harmless:
        return "harmless"
    if drop.low > brittle:
        return "brittle"
    if drop.low > harmless and drop.high < brittle:
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
            f"reproduced when {', '.join(harmless)} are harmless and {', '.join(brittle)} "
            f"brittle; not reproduced when one of them is shown otherwise (a harmless one's drop "
            f"above {HARMLESS:.0%}, a brittle one's below {BRITTLE:.0%}); undecided otherwise."
        )
    else:
        rule = zones + (
            f"reproduced when some feature is harmless and some brittle; not reproduced when "
            f"every feature's drop lies above {HARMLESS:.0%} (none harmless) or every one below "
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
                lambda m, column=column: worst_drop(m, column),
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
        zones_found = ", ".join(
            f"{f} {d}" + (f" {zone[f]}" if zone[f] else "") for f, d in drops.items()
        )
        return _over_margins(
            lambda scale: judge(drops, gain, scale),
            f"drop from the default context to the worst magnitude per feature (95% CI over "
            f"seeds): {zones_found}; harmless below {HARMLESS * gain:.4g}, brittle above "
            f"{BRITTLE * gain:.4g} ({HARMLESS:.0%} and {BRITTLE:.0%} of the gain {gain:.4g})",
        )

    def judge(drops: dict[str, Interval], gain: float, scale: float) -> bool | None:
        """The rule's verdict with the zones' bounds times ``scale``."""
        zone = {f: _zone(d, gain, scale) for f, d in drops.items()}
        not_harmless = {f for f, d in drops.items() if d.low > scale * HARMLESS * gain}
        not_brittle = {f for f, d in drops.items() if d.high < scale * BRITTLE * gain}

        def named(feature: str, wanted: str, ruled_out: set[str]) -> bool | None:
            """In the wanted zone: True; its interval rules that out: False; else undecided."""
            if zone.get(feature) == wanted:
                return True
            return False if feature in ruled_out else None

        if harmless or brittle:
            return _all(
                [named(f, "harmless", not_harmless) for f in harmless]
                + [named(f, "brittle", not_brittle) for f in brittle]
            )
        if {"harmless", "brittle"} <= set(zone.values()):
            return True
        if not_harmless == set(drops) or not_brittle == set(drops):
            return False
        return None

    return Check(f"{rule} {MARGIN_RULE}", decide)


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
        "reproduced when the 95% intervals (over seeds, each seed's agents with all their "
        "contexts) of "
        + "; of ".join(parts)
        + " all lie above 0; not reproduced when one lies below 0; undecided otherwise."
    )

    def decide(runs: Mapping[str, RunDir], gain: float) -> Verdict:
        (run,) = runs.values()
        spec, cells = _cells(run)
        decisions, text = [], []

        def paired(name: str, first: pd.DataFrame, second: pd.DataFrame) -> None:
            diff = (per_seed_means(first) - per_seed_means(second)).dropna()
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
                per_seed_means(outside[outside["variant"] == v]).dropna().to_numpy(float)
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
        return Verdict(
            _all(decisions), "; ".join(text) + " (95% CI over seeds; above 0 reproduces)"
        )

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
    "reproduced when the exact optimality gap of the best deterministic context-oblivious policy "
    "on the paper's 3-state cMDP is above 0 (solved exactly: no sampling, no interval).",
    _tabular,
    gated=False,
)
