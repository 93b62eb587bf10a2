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
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import jax
import numpy as np
import yaml

from contextrl.agents import ConfigError
from contextrl.analysis import metrics
from contextrl.analysis.intervals import Interval, paired_bootstrap_ci
from contextrl.analysis.report import Figure as ReportFigure
from contextrl.analysis.report import Section, render
from contextrl.experiments.analyze import run_cells, score_matrices
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
# A feature is brittle when some magnitude costs the default agent more than this fraction of what it
# gained over a random policy at the default context, harmless when no magnitude does.
BRITTLE_FRACTION = 0.25


@dataclasses.dataclass(frozen=True)
class Verdict:
    """Whether a claim holds at the budget it ran at (None: the intervals do not decide it)."""

    holds: bool | None
    evidence: str

    @property
    def word(self) -> str:
        return {True: "holds", False: "does not hold", None: "undecided"}[self.holds]


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


def gap_check(at_least: float) -> Callable[[Mapping[str, RunDir]], Verdict]:
    """Specialists beat the general agent by more than ``at_least`` (the gap's interval decides)."""

    def check(runs: Mapping[str, RunDir]) -> Verdict:
        (run,) = runs.values()
        spec, cells = _cells(run)
        stats = gap_statistics(spec, cells)[spec.variants[0]]
        seeds = stats.per_seed()
        return Verdict(
            _decide(stats.gap, at_least),
            f"gap E_c[G_specialist − G_general] = {stats.gap} (95% CI; the claim needs it above "
            f"{at_least:g}); P(specialist > general) = {stats.improvement}; mean return per seed: "
            f"general {_numbers(seeds['general'])}, specialists {_numbers(seeds['specialists'])}",
        )

    return check


def _numbers(values) -> str:
    return " ".join(f"{v:.0f}" for v in values)


def _difference(a, b, *, reps: int, seed: int) -> Interval:
    """Mean return of ``a`` minus ``b`` with a stratified-bootstrap interval; a one-seed matrix (a
    PB2 run's best member) is read as one run per test context, so contexts are resampled."""
    a, b = (m.T if m.shape[0] == 1 else m for m in (a, b))
    return paired_bootstrap_ci(
        a,
        b,
        lambda x, y: metrics.aggregate_mean(x) - metrics.aggregate_mean(y),
        reps=reps,
        seed=seed,
    )


def _variant_difference(runs: Mapping[str, RunDir], a: str, b: str) -> tuple[dict, Interval]:
    """Score matrices by variant over all the figure's runs (a part per variant, or one run), and
    the mean test return of variant ``a`` minus ``b``."""
    scores, spec = {}, None
    for run in runs.values():
        spec, cells = _cells(run)
        scores.update(score_matrices(cells, cells["variant"]))
    diff = _difference(scores[a].matrix, scores[b].matrix, reps=spec.bootstrap_reps, seed=spec.seed)
    return scores, diff


def _means(scores: dict, a: str, b: str) -> str:
    return ", ".join(f"{v} {metrics.aggregate_mean(scores[v].matrix):.4g}" for v in (a, b))


def better_check(a: str, b: str) -> Callable[[Mapping[str, RunDir]], Verdict]:
    """Variant ``a``'s mean test return is above ``b``'s."""

    def check(runs: Mapping[str, RunDir]) -> Verdict:
        scores, diff = _variant_difference(runs, a, b)
        return Verdict(
            _decide(diff),
            f"mean test return {a} − {b} = {diff} (95% CI; the claim needs it above 0); "
            + _means(scores, a, b),
        )

    return check


def similar_check(a: str, b: str) -> Callable[[Mapping[str, RunDir]], Verdict]:
    """No difference between the mean test returns of ``a`` and ``b``: the interval includes 0."""

    def check(runs: Mapping[str, RunDir]) -> Verdict:
        scores, diff = _variant_difference(runs, a, b)
        return Verdict(
            diff.low <= 0.0 <= diff.high,
            f"mean test return {a} − {b} = {diff} (95% CI; the claim needs it to include 0); "
            + _means(scores, a, b),
        )

    return check


def _drop(runs: np.ndarray, default_column: int) -> np.ndarray:
    """How far the worst magnitude's mean return falls below the default's (``runs``: seeds ×
    magnitudes, with any leading axes of bootstrap samples)."""
    means = np.ma.filled(np.ma.mean(runs, axis=-2), np.nan)
    return means[..., default_column] - np.nanmin(means, axis=-1)


def sensitivity_check(
    harmless: tuple[str, ...] = (), brittle: tuple[str, ...] = ()
) -> Callable[[Mapping[str, RunDir]], Verdict]:
    """The named features are harmless or brittle (none named: at least one of each exists).

    A feature's drop is the default context's mean return minus its worst magnitude's, with a
    bootstrap interval over seeds; the threshold is ``BRITTLE_FRACTION`` of what the agent gains over
    a random policy at the default context."""

    def check(runs: Mapping[str, RunDir]) -> Verdict:
        (run,) = runs.values()
        spec, cells = _cells(run)
        lines = magnitude_lines(cells)
        training = run.training()
        rng = np.random.default_rng(spec.seed)
        drops = {}
        default = None
        for feature, by_variant in lines.items():
            x, matrix = by_variant[spec.variants[0]]
            column = int(np.flatnonzero(np.isclose(x, 1.0))[0])
            default = float(np.ma.mean(matrix[:, column]))
            rows = rng.integers(0, matrix.shape[0], size=(spec.bootstrap_reps, matrix.shape[0]))
            low, high = np.percentile(_drop(matrix[rows], column), [2.5, 97.5])
            drops[feature] = Interval(float(_drop(matrix, column)), float(low), float(high))
        # an untrained (random) agent has no training rows: then nothing is called brittle
        random = float(training["random_return"].mean()) if "random_return" in training else np.nan
        if random >= default:  # (False for an untrained agent's nan)
            return Verdict(
                None,
                f"the trained agent does not beat a random policy at the default context (mean "
                f"return {default:.4g} against {random:.4g}) at this budget: no feature can be "
                "called brittle or harmless",
            )
        threshold = BRITTLE_FRACTION * (default - random)
        kind = {f: _decide(d, threshold) for f, d in drops.items()}  # True brittle, False harmless
        if harmless or brittle:
            holds = _all(
                [kind.get(f) is True for f in brittle if kind.get(f) is not None]
                + [kind.get(f) is False for f in harmless if kind.get(f) is not None]
                + [None for f in (*brittle, *harmless) if kind.get(f) is None]
            )
        else:
            found = set(kind.values())
            holds = True if {True, False} <= found else (None if None in found else False)
        named = ", ".join(
            f"{f} {d}" + {True: " brittle", False: " harmless", None: ""}[kind[f]]
            for f, d in drops.items()
        )
        return Verdict(
            holds,
            f"drop from the default context to the worst magnitude per feature (95% CI over "
            f"seeds): {named}; brittle above {threshold:.4g} = {BRITTLE_FRACTION} × (default "
            f"{default:.4g} − random policy {random:.4g})",
        )

    return check


def extrapolation_check(runs: Mapping[str, RunDir]) -> Verdict:
    """For every variant, the mean return on interpolation contexts is above that on contexts
    outside the training range in both features (per-seed means, bootstrap over seeds)."""
    (run,) = runs.values()
    spec, cells = _cells(run)
    decisions, parts = [], []
    for variant in spec.variants:
        mine = cells[cells["variant"] == variant]
        per_seed = {
            region: mine[mine["region"] == region].groupby("seed")["return"].mean()
            for region in (REGIONS[0], REGIONS[3])
        }
        empty = [region for region, means in per_seed.items() if means.isna().all()]
        if empty:
            decisions.append(None)
            parts.append(f"{variant}: no test context returned in {' or '.join(empty)}")
            continue
        inside, outside = (per_seed[r].to_numpy(float)[None, :] for r in (REGIONS[0], REGIONS[3]))
        diff = _difference(inside, outside, reps=spec.bootstrap_reps, seed=spec.seed)
        decisions.append(_decide(diff))
        parts.append(f"{variant}: interpolation − extrapolation (both) = {diff}")
    return Verdict(_all(decisions), "; ".join(parts) + " (95% CI over seeds; above 0 holds)")


def tabular_check(runs: Mapping[str, RunDir]) -> Verdict:
    """The paper's 3-state cMDP has a context-oblivious optimality gap above zero (exact)."""
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


@dataclasses.dataclass(frozen=True)
class PaperFigure:
    """A figure of the paper: its spec file(s), the check of its claim and its small budget."""

    name: str
    check: Callable[[Mapping[str, RunDir]], Verdict]
    small: Mapping[str, Any]  # spec fields for two CPU cores (agent_options merge into the spec's)
    parts: tuple[str, ...] = ()  # spec files (stems) of a figure of several runs

    def files(self) -> dict[str, Path]:
        stems = self.parts or (self.name,)
        return {
            stem.removeprefix(self.name + "_") or stem: SPEC_FOLDER / f"{stem}.yaml"
            for stem in stems
        }

    def header(self, key: str) -> str:
        """The ``# Paper:`` or ``# Claim:`` line of the figure's (first) spec."""
        text = next(iter(self.files().values())).read_text(encoding="utf-8")
        prefix = f"# {key}:"
        lines = [
            line[len(prefix) :].strip() for line in text.splitlines() if line.startswith(prefix)
        ]
        return lines[0] if lines else ""


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
        f"Here, at the {scale} budget: the claim {verdict.word}. {verdict.evidence}.",
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
    """``docs/paper.md``: every figure with its claim and, per scale run under ``root``, our
    statistic, the budget, the time it took and whether the claim held."""
    lines = [
        "# The paper, reproduced",
        "",
        "Every figure of the paper with an experiment behind it, its claim, and what the library "
        "measured. Generated by `contextrl paper page` from the run folders of `contextrl paper run` "
        f"(here `{root}`: specs, manifests, results, curves and timings; `contextrl report RUN` "
        "draws a run's figures); a figure not run says so. *holds* / *does not hold*: the 95% interval "
        "decides; *undecided*: it does not at that budget. The specs are in `examples/paper/` "
        "(shipped as `contextrl/paper/`); `--scale small` runs the budget two CPU cores afford, "
        "stated per figure below, with the time the paper's budget would take (extrapolated per "
        "training step from the runs of the same environment and agent); on a Ray cluster it is "
        "`contextrl paper run FIGURE --scale paper --executor ray --address auto`. The paper's "
        "Figure 1 (CARLFetch at three target distances and three ground frictions) is a picture, "
        "not an experiment: `contextrl render Fetch --grid "
        "target_distance=2,6,10 --grid friction=0.05,0.6,1.0` draws it (families/brax.md).",
        "",
    ]
    for figure in FIGURES.values():
        lines += [
            f"## {figure.name}",
            "",
            f"**Paper**: {figure.header('Paper')}  ",
            f"**Claim**: {figure.header('Claim')}  ",
            f"**Run**: `contextrl paper run {figure.name} --scale small` (the paper's budget: "
            "`--scale paper`)  ",
            "**Budgets**: "
            + "; ".join(f"{scale}: {_budgets(figure, scale)}" for scale in ("paper", "small")),
            "",
        ]
        ran = False
        for scale in SCALES:
            runs = finished_runs(figure, root, scale)
            if runs is None:
                continue
            ran = True
            verdict = figure.check(runs)
            budget = _budgets(figure, scale, runs)
            seconds = sum(wall_seconds(r) for r in runs.values())
            machines = _machines(runs.values())
            lines += [
                f"- **{scale} budget** ({budget}; {duration(seconds)} on {machines}): the claim "
                f"**{verdict.word}**. {verdict.evidence}.",
            ]
        if not ran:
            lines.append(
                f"- Not run yet. Estimated time at the small budget: "
                f"{estimate(figure, 'small', root)}."
            )
        trains = any(
            parse_spec(spec_data(figure, p, "paper")).trains_agents for p in figure.files()
        )
        if trains and finished_runs(figure, root, "paper") is None:
            lines.append(f"- **paper budget**: not run; {estimate(figure, 'paper', root)}.")
        lines.append("")
    return "\n".join(lines)


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
    parts = [f"{_steps(spec):,} training steps"] if spec.trains_agents else []
    for field in ("seeds", "num_contexts", "num_train_contexts", "population", "rounds"):
        if hasattr(spec, field) and field not in spec.unused_fields and spec.trains_agents:
            parts.append(f"{field.replace('num_', '').replace('_', ' ')} {getattr(spec, field)}")
    return ", ".join(parts) or "exact solution"


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
            gap_check(30.0),
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
                ("kirk_cartpole", extrapolation_check, _SMALL_C51),
                ("kirk_pendulum_gravity_dt", extrapolation_check, _SMALL_SAC),
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
