"""Run, resume and report an experiment: what ``contextrl run`` and ``contextrl report`` call. A run is
opened (created, or found with its spec) and then carried on: what is unfinished runs, the report is
written."""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from typing import Any

from contextrl.compile_cache import use_compilation_cache
from contextrl.experiments.executors import EXECUTORS, run_chunks
from contextrl.experiments.more_seeds import finish_adding_seeds
from contextrl.experiments.plan import expand
from contextrl.experiments.protocol import protocol_of
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


def check_executor(executor: str) -> None:
    """Refuse an executor that does not exist, before anything is created."""
    if executor not in EXECUTORS:
        raise SpecError(f"executor: unknown executor {executor!r}; choose one of {list(EXECUTORS)}")


def open_run(
    spec: CommonSpec | Mapping[str, Any] | None = None,
    *,
    resume: str | os.PathLike | None = None,
    out: str | os.PathLike | None = None,
    root: str | os.PathLike = "runs",
) -> tuple[RunDir, CommonSpec]:
    """The run to carry on and its validated spec: a new run directory for ``spec`` (``out``, else a
    fresh folder under ``root``), or, with ``resume``, the run directory there with its own spec."""
    if (spec is None) == (resume is None):
        raise TypeError("open_run: give either a spec (a new run) or resume=RUN_DIRECTORY")
    xla_cpu_workaround()  # effective when JAX has not computed anything yet here
    use_compilation_cache()
    if resume is not None:
        run = RunDir(resume)
        finish_adding_seeds(run)  # where a process adding seeds was killed part-way
        return run, prepare(run.spec())
    spec = prepare(spec)
    return RunDir.create(spec, root=root, out=None if out is None else str(out)), spec


def carry_on(
    run: RunDir,
    spec: CommonSpec,
    *,
    executor: str = "local",
    address: str | None = None,
    max_chunks: int | None = None,
    progress: bool = True,
    verbose: bool = False,
    report: bool = True,
) -> Summary:
    """Run what is unfinished in ``run`` (failed chunks are retried), then write its report: the
    protocol's own ``execute`` where it has one (``verbose``: Ray's and Tune's own output on the
    terminal, not in the run's ray/ray.log), else the plan's chunks of trials on ``executor``."""
    check_executor(executor)
    use_compilation_cache()
    plan = expand(spec)
    options = {
        "executor": executor,
        "address": address,
        "max_chunks": max_chunks,
        "progress": progress,
    }
    execute = protocol_of(spec).execute
    if execute is not None:
        summary = execute(spec, run, plan, **options, verbose=verbose)
    else:
        summary = run_chunks(run, plan, **options, save_params=spec.agent_entry().trained)
    if report:
        build_report(run)
    return summary


def run_experiment(
    spec: CommonSpec | Mapping[str, Any] | None = None,
    *,
    resume: str | os.PathLike | None = None,
    out: str | os.PathLike | None = None,
    root: str | os.PathLike = "runs",
    progress: bool = True,
    **options: Any,
) -> tuple[RunDir, Summary]:
    """The one entry of a run: validate ``spec`` and create its run directory, or, with ``resume``,
    carry on the run there; run every unfinished trial and write the report (``options``: those of
    :func:`carry_on`)."""
    check_executor(options.get("executor", "local"))  # before a run directory is created
    run, spec = open_run(spec, resume=resume, out=out, root=root)
    if progress and resume is None:
        print(f"run directory: {run.path}", file=sys.stderr, flush=True)
    return run, carry_on(run, spec, progress=progress, **options)


def resume(path: str | os.PathLike, **options: Any) -> tuple[RunDir, Summary]:
    """Carry on an interrupted run: ``run_experiment(resume=path, ...)``."""
    return run_experiment(resume=path, **options)


def report(path: str | os.PathLike) -> str:
    """Rebuild ``report.html`` of a run from its files; returns the report's path."""
    return build_report(RunDir(path))
