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

from contextrl.analysis import plots
from contextrl.analysis.intervals import interval_estimates
from contextrl.analysis.report import Section, render
from contextrl.experiments.analyze import (
    CI_METRICS,
    agent_label,
    curves_by_label,
    figure,
    interval_rows,
    natural_key,
    return_lines,
    score_matrix,
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


def _feature_views(results: pd.DataFrame) -> list[tuple[str, pd.DataFrame, str]]:
    """(x label, rows, x column): the magnitude A per scaled feature for sensitivity runs (a
    ``feature`` column), else each varied context feature."""
    if "feature" in results and "magnitude" in results:
        return [
            (f"A × default {feature}", group, "magnitude")
            for feature, group in results.groupby("feature", sort=False)
        ]
    return [(name, results, f"ctx.{name}") for name in varying_features(results)]


def compare_runs(paths: Sequence[str | os.PathLike], out: str | os.PathLike) -> Path:
    """Write one HTML report overlaying the runs at ``paths`` (same protocol); returns its path."""
    runs = [RunDir(p) for p in paths]
    specs = [run.spec() for run in runs]
    protocols = sorted({spec.protocol for spec in specs})
    if len(protocols) > 1:
        raise SpecError(
            f"report: runs of different protocols {protocols} cannot be overlaid; "
            "compare runs of one protocol"
        )
    if not specs[0].trains_agents:
        raise SpecError(f"report: the {protocols[0]} protocol has no agents to overlay")
    labels = _labels(runs)
    frames, curve_frames, rows = [], [], []
    for label, run, spec in zip(labels, runs, specs, strict=True):
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
            frames.append(results.assign(overlay=label + ": " + agent_label(results)))
        if len(curves):
            curve_frames.append(curves.assign(overlay=label + ": " + agent_label(curves)))
    if not frames:
        raise SpecError("report: none of these runs has finished results yet")
    results = pd.concat(frames, ignore_index=True)
    seed = specs[0].seed
    reps = min(spec.bootstrap_reps for spec in specs)
    scores = {
        label: score_matrix(group)
        for label, group in sorted(results.groupby("overlay"), key=lambda g: natural_key(g[0]))
    }
    cis = interval_estimates(scores, CI_METRICS, reps=reps, seed=seed)
    figures = [
        figure(
            "compare-intervals",
            plots.intervals(cis),
            "Aggregate test return per run and agent with stratified-bootstrap 95% CIs",
        )
    ]
    for xlabel, group, column in _feature_views(results):
        lines = return_lines(group, column, group["overlay"])
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
            [f"{len(runs)} runs of the {protocols[0]} protocol, overlaid."],
            [("Runs", rows)],
        ),
        Section(
            "Comparison", tables=[("Test return (95% CI)", interval_rows(cis))], figures=figures
        ),
    ]
    html = render(f"contextrl {protocols[0]}: {' vs '.join(labels)}", sections, {"runs": rows})
    return write_text(Path(out), html)
