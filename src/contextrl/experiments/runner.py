"""Run, resume and report an experiment: what ``contextrl run`` and ``contextrl report`` call."""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Mapping
from typing import Any

from contextrl.experiments.analyze import build_report, tabular_frame
from contextrl.experiments.executors import EXECUTORS, Summary, run_local, run_ray
from contextrl.experiments.protocols import expand
from contextrl.experiments.runs import RunDir, write_parquet
from contextrl.experiments.spec import CommonSpec, SpecError, parse_spec
from contextrl.experiments.trials import check_agent


def prepare(spec: CommonSpec | Mapping[str, Any]) -> CommonSpec:
    """A fully validated spec (fields, environment, features, agent options); nothing runs."""
    spec = spec if isinstance(spec, CommonSpec) else parse_spec(spec)
    if spec.protocol != "tabular":
        check_agent(spec)
    return spec


def _execute(
    run: RunDir, spec: CommonSpec, executor: str, address, max_chunks, progress
) -> Summary:
    if executor not in EXECUTORS:
        raise SpecError(f"executor: unknown executor {executor!r}; choose one of {list(EXECUTORS)}")
    start = time.perf_counter()
    if spec.protocol == "tabular":
        if not run.finished():
            write_parquet(run.result_path(0), tabular_frame(spec))
        return Summary([0], [], [], [], time.perf_counter() - start)
    plan = expand(spec)
    save = spec.agent != "random"
    if executor == "ray":
        return run_ray(
            run, plan, address=address, max_chunks=max_chunks, progress=progress, save_params=save
        )
    return run_local(run, plan, max_chunks=max_chunks, progress=progress, save_params=save)


def run_experiment(
    spec: CommonSpec | Mapping[str, Any],
    *,
    out: str | os.PathLike | None = None,
    root: str | os.PathLike = "runs",
    executor: str = "local",
    address: str | None = None,
    max_chunks: int | None = None,
    progress: bool = True,
    report: bool = True,
) -> tuple[RunDir, Summary]:
    """Validate ``spec``, create its run directory, run every trial and write the report."""
    spec = prepare(spec)
    if executor not in EXECUTORS:
        raise SpecError(f"executor: unknown executor {executor!r}; choose one of {list(EXECUTORS)}")
    run = RunDir.create(spec, root=root, out=None if out is None else str(out))
    if progress:
        print(f"run directory: {run.path}", file=sys.stderr, flush=True)
    summary = _execute(run, spec, executor, address, max_chunks, progress)
    if report:
        build_report(run)
    return run, summary


def resume(
    path: str | os.PathLike,
    *,
    executor: str = "local",
    address: str | None = None,
    max_chunks: int | None = None,
    progress: bool = True,
    report: bool = True,
) -> tuple[RunDir, Summary]:
    """Run the chunks of an interrupted run that have no results yet (failed ones are retried)."""
    run = RunDir(path)
    spec = prepare(run.spec())
    summary = _execute(run, spec, executor, address, max_chunks, progress)
    if report:
        build_report(run)
    return run, summary


def report(path: str | os.PathLike) -> str:
    """Rebuild ``report.html`` of a run from its files; returns the report's path."""
    return build_report(RunDir(path))
