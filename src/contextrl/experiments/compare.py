"""``contextrl report RUN_A RUN_B …``: several runs of one protocol overlaid in one report.

Each run keeps its own results; lines are labelled ``run: agent`` so two runs of the same spec with a
different agent, budget or environment version can be read side by side: test return with CIs, return
against each varied feature (the magnitude A for sensitivity), and training curves.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

import contextrl as crl
from contextrl.analysis import plots
from contextrl.analysis.intervals import SAMPLED
from contextrl.analysis.report import Section, render
from contextrl.analysis.scores import (
    agent_label,
    drawn_intervals,
    interval_title,
    magnitude_lines,
    missing_rows,
    return_lines,
    score_intervals,
    score_matrices,
)
from contextrl.experiments.plan import expand
from contextrl.experiments.reports import (
    MISSING_TEXT,
    changed_features,
    curves_by_label,
    figure,
    run_cells,
    varying_features,
)
from contextrl.experiments.runs import RunDir, write_text
from contextrl.experiments.spec import SpecError


def _labels(runs: Sequence[RunDir]) -> list[str]:
    """Each run's spec name, or its folder name where names repeat."""
    names = [run.spec().name for run in runs]
    if len(set(names)) == len(names):
        return names
    folders = [run.path.name for run in runs]
    if len(set(folders)) == len(folders):
        return folders
    return [str(run.path) for run in runs]


def _feature_lines(results: pd.DataFrame) -> list[tuple[str, dict]]:
    """(x label, lines per run and agent): the magnitude A per scaled feature for sensitivity runs
    (a ``feature`` column; the default context is every feature's A = 1), else each varied context
    feature."""
    if "feature" in results and "magnitude" in results:
        return [
            (f"A × default {feature}", lines)
            for feature, lines in magnitude_lines(results, "overlay").items()
        ]
    return [
        (name, return_lines(results, f"ctx.{name}", results["overlay"]))
        for name in varying_features(results)
    ]


def _differences(specs: Sequence, plans: Sequence) -> dict[str, list[str]]:
    """What sets the runs' axes apart, per run: protocol, environment and the context features
    their contexts change (``reports.changed_features``); only the keys on which runs differ."""
    keys = {
        "protocol": [spec.protocol for spec in specs],
        "env": [crl.spec(spec.env).id for spec in specs],
        "features": [", ".join(changed_features(plan)) or "none" for plan in plans],
    }
    return {key: values for key, values in keys.items() if len(set(values)) > 1}


def compare_runs(
    paths: Sequence[str | os.PathLike], out: str | os.PathLike, force: bool = False
) -> Path:
    """Write one HTML report overlaying the runs at ``paths``; returns its path. Runs of different
    protocols, environments or varied features are refused (their returns do not share an axis),
    or with ``force`` overlaid with each run's label naming how it differs."""
    resolved = [Path(p).resolve() for p in paths]
    twice = sorted({str(p) for p, r in zip(paths, resolved, strict=True) if resolved.count(r) > 1})
    if twice:
        raise SpecError(f"report: {', '.join(twice)} given twice; give each run once")
    runs = [RunDir(p) for p in paths]
    specs = [run.spec() for run in runs]
    untrained = [spec.protocol for spec in specs if not spec.trains_agents]
    if untrained:
        raise SpecError(f"report: the {untrained[0]} protocol has no agents to overlay")
    plans = [expand(spec) for spec in specs]
    differ = _differences(specs, plans)
    labels = _labels(runs)
    if differ and not force:
        said = "; ".join(
            f"{key} "
            + ", ".join(f"{label}: {value}" for label, value in zip(labels, values, strict=True))
            for key, values in differ.items()
        )
        raise SpecError(
            f"report: these runs differ in {' and '.join(differ)} ({said}), so their returns do not "
            "share an axis; compare runs of one protocol, environment and varied features, or "
            "pass --force to overlay them labelled"
        )
    if differ:
        labels = [
            f"{label} [{', '.join(values[i] for values in differ.values())}]"
            for i, label in enumerate(labels)
        ]
    protocols = list(dict.fromkeys(spec.protocol for spec in specs))
    frames, curve_frames, rows = [], [], []
    for label, run, spec, plan in zip(labels, runs, specs, plans, strict=True):
        results, curves = run.results(), run.curves()
        rows.append(
            {
                "run": label,
                "folder": str(run.path),
                "env": spec.env,
                "agent": spec.agent,
                "variants": ", ".join(spec.variants),
                "seeds": spec.seeds,
                "trials finished": int(results["trial"].nunique()) if len(results) else 0,
            }
        )
        if len(results):
            cells = run_cells(run, plan, results)
            frames.append(cells.assign(overlay=label + ": " + agent_label(cells)))
        if len(curves):
            curve_frames.append(curves.assign(overlay=label + ": " + agent_label(curves)))
    if not frames:
        raise SpecError("report: none of these runs has finished results yet")
    results = pd.concat(frames, ignore_index=True)
    seed = specs[0].seed
    reps = min(spec.bootstrap_reps for spec in specs)
    scores = score_matrices(results, results["overlay"])
    designs = {spec.test_contexts for spec in specs}
    contexts = designs.pop() if len(designs) == 1 else SAMPLED  # mixed: the wider design
    cis, ci_rows = score_intervals(scores, contexts=contexts, reps=reps, seed=seed)
    figures = [
        figure(
            "compare-intervals",
            plots.intervals(drawn_intervals(cis, scores)),
            interval_title("Aggregate test return per run and agent", scores, contexts),
        )
    ]
    missing = missing_rows(scores)
    for xlabel, lines in _feature_lines(results):
        if lines:
            slug = "".join(ch if ch.isalnum() else "-" for ch in xlabel)
            figures.append(
                figure(
                    f"compare-return-vs-{slug}",
                    plots.return_vs_feature(lines, xlabel=xlabel, seed=seed),
                    f"Mean test return against {xlabel} per run and agent (95% band over seeds)",
                )
            )
    if curve_frames:
        steps, by_label = {}, {}
        for frame in curve_frames:  # each run on its own steps (budgets may differ)
            run_steps, lines = curves_by_label(frame, lambda f: f["overlay"])
            by_label.update(lines)
            steps.update(dict.fromkeys(lines, run_steps))
        figures.append(
            figure(
                "compare-training",
                plots.training_curves(steps, by_label, title="Training return", seed=seed),
                "Training return per run and agent with a 95% bootstrap band over seeds",
            )
        )
    sections = [
        Section(
            "Runs",
            [
                f"{len(runs)} runs of the {' and '.join(protocols)} protocol, overlaid."
                + (
                    f" They differ in {' and '.join(differ)} (--force); each label names its own."
                    if differ
                    else ""
                )
            ],
            [("Runs", rows)],
        ),
        Section(
            "Comparison",
            [MISSING_TEXT] if missing else [],
            [(interval_title("Test return", scores, contexts), ci_rows)]
            + ([("Missing results", missing)] if missing else []),
            figures,
        ),
    ]
    html = render(
        f"contextrl {' / '.join(protocols)}: {' vs '.join(labels)}", sections, {"runs": rows}
    )
    return write_text(Path(out), html)
