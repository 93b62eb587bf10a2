"""Run, resume and report an experiment: what ``contextrl run`` and ``contextrl report`` call."""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from typing import Any

from contextrl.experiments.analyze import build_report
from contextrl.experiments.executors import EXECUTORS, Summary
from contextrl.experiments.protocols import expand
from contextrl.experiments.runs import RunDir
from contextrl.experiments.spec import CommonSpec, SpecError, parse_spec


def prepare(spec: CommonSpec | Mapping[str, Any]) -> CommonSpec:
    """A fully validated spec (fields, environment, features, agent options); nothing runs."""
    if isinstance(spec, CommonSpec):
        spec.validate()
        return spec
    return parse_spec(spec)


def _execute(
    run: RunDir, spec: CommonSpec, executor: str, address, max_chunks, progress
) -> Summary:
    if executor not in EXECUTORS:
        raise SpecError(f"executor: unknown executor {executor!r}; choose one of {list(EXECUTORS)}")
    return spec.execute(
        run,
        expand(spec),
        executor=executor,
        address=address,
        max_chunks=max_chunks,
        progress=progress,
    )


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
