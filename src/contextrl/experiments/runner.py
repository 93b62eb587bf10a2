"""Run, resume and report an experiment: what ``contextrl run`` and ``contextrl report`` call."""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from typing import Any

from contextrl.compile_cache import use_compilation_cache
from contextrl.experiments.executors import EXECUTORS, run_chunks
from contextrl.experiments.plan import expand
from contextrl.experiments.reports import build_report
from contextrl.experiments.runs import RunDir, Summary
from contextrl.experiments.spec import CommonSpec, SpecError, parse_spec
from contextrl.xla_flags import xla_cpu_workaround


def prepare(spec: CommonSpec | Mapping[str, Any]) -> CommonSpec:
    """A fully validated spec (fields, environment, features, agent options); nothing runs."""
    if isinstance(spec, CommonSpec):
        spec.validate()
        return spec
    return parse_spec(spec)


def _execute(
    run: RunDir, spec: CommonSpec, executor: str, address, max_chunks, progress, verbose
) -> Summary:
    """Run what is unfinished in ``run``: the protocol's own ``execute`` where it has one (``verbose``:
    it shows Ray's own output), else the plan's chunks of trials on ``executor``."""
    if executor not in EXECUTORS:
        raise SpecError(f"executor: unknown executor {executor!r}; choose one of {list(EXECUTORS)}")
    plan = expand(spec)
    options = {
        "executor": executor,
        "address": address,
        "max_chunks": max_chunks,
        "progress": progress,
    }
    if spec.execute is not None:
        return spec.execute(run, plan, **options, verbose=verbose)
    return run_chunks(run, plan, **options, save_params=spec.agent_entry().trained)


def run_experiment(
    spec: CommonSpec | Mapping[str, Any],
    *,
    out: str | os.PathLike | None = None,
    root: str | os.PathLike = "runs",
    executor: str = "local",
    address: str | None = None,
    max_chunks: int | None = None,
    progress: bool = True,
    verbose: bool = False,
    report: bool = True,
) -> tuple[RunDir, Summary]:
    """Validate ``spec``, create its run directory, run every trial and write the report
    (``verbose``: as for :func:`resume`)."""
    xla_cpu_workaround()  # effective when JAX has not computed anything yet here
    use_compilation_cache()
    spec = prepare(spec)
    if executor not in EXECUTORS:
        raise SpecError(f"executor: unknown executor {executor!r}; choose one of {list(EXECUTORS)}")
    run = RunDir.create(spec, root=root, out=None if out is None else str(out))
    if progress:
        print(f"run directory: {run.path}", file=sys.stderr, flush=True)
    summary = _execute(run, spec, executor, address, max_chunks, progress, verbose)
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
    verbose: bool = False,
    report: bool = True,
) -> tuple[RunDir, Summary]:
    """Run the chunks of an interrupted run that have no results yet (failed ones are retried);
    ``verbose``: Ray's and Tune's own output on the terminal (hpo), not in the run's ray/ray.log."""
    xla_cpu_workaround()  # effective when JAX has not computed anything yet here
    use_compilation_cache()
    run = RunDir(path)
    spec = prepare(run.spec())
    summary = _execute(run, spec, executor, address, max_chunks, progress, verbose)
    if report:
        build_report(run)
    return run, summary


def report(path: str | os.PathLike) -> str:
    """Rebuild ``report.html`` of a run from its files; returns the report's path."""
    return build_report(RunDir(path))
