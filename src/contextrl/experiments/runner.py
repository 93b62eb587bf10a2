"""Run, resume, preview and report an experiment: what ``contextrl run`` and ``contextrl report`` call.
A run is opened (created, or found with its spec) and then carried on: what is unfinished runs, the
report is written."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from contextrl.compile_cache import use_compilation_cache
from contextrl.experiments.executors import EXECUTORS, connect, run_chunks
from contextrl.experiments.more_seeds import finish_adding_seeds
from contextrl.experiments.plan import expand
from contextrl.experiments.planning import describe_plan
from contextrl.experiments.protocol import protocol_of
from contextrl.experiments.reports import build_report
from contextrl.experiments.runs import RunDir, Summary
from contextrl.experiments.spec import CommonSpec, SpecError, parse_spec
from contextrl.experiments.tensorboard import TensorBoardLog
from contextrl.xla_flags import xla_cpu_workaround

LOGS = ("tensorboard",)


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


def _where(out, root) -> str:
    return f"--out {out}" if out is not None else f"--root {root}"


def _unwritable(out, root, reason: str, filename) -> SpecError:
    return SpecError(
        f"{_where(out, root)}: cannot create the run directory ({reason}: {filename}); choose a "
        "writable folder"
    )


def new_run_path(spec: CommonSpec, *, out=None, root: str | os.PathLike = "runs") -> Path:
    """The folder a new run of ``spec`` would be created in, checked without creating anything: one
    that holds a run (FileExistsError) or is a file, or whose nearest existing parent is not a
    writable folder, is refused."""
    path = RunDir.new_path(spec, root=root, out=None if out is None else str(out))
    parent = path
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise _unwritable(out, root, "Not a directory", path)
    if not os.access(parent, os.W_OK):
        raise _unwritable(out, root, "Permission denied", parent)
    return path


def resumable(resume: str | os.PathLike) -> RunDir:
    """The run directory at ``resume``, refused with the folder to give where it holds no run."""
    if not (Path(resume) / "spec.yaml").is_file():
        what = "no run directory" if Path(resume).is_dir() else "no such folder"
        raise SpecError(
            f"--resume {resume}: {what} (a run directory holds spec.yaml); "
            "give the folder `contextrl run` printed"
        )
    return RunDir(resume)


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
        run = resumable(resume)
        finish_adding_seeds(run)  # where a process adding seeds was killed part-way
        return run, prepare(run.spec())
    spec = prepare(spec)
    return _create(spec, out, root), spec


def _create(spec: CommonSpec, out, root) -> RunDir:
    """The new run directory of a validated ``spec`` (both settings are idempotent)."""
    xla_cpu_workaround()
    use_compilation_cache()
    try:
        return RunDir.create(spec, root=root, out=None if out is None else str(out))
    except FileExistsError:
        raise  # names the run there and how to resume it
    except OSError as error:
        raise _unwritable(out, root, error.strerror or str(error), error.filename) from None


def preview(
    spec: CommonSpec | Mapping[str, Any] | None = None,
    *,
    resume: str | os.PathLike | None = None,
    out: str | os.PathLike | None = None,
    root: str | os.PathLike = "runs",
    executor: str = "local",
    address: str | None = None,
    estimate: bool = False,
) -> str:
    """A dry run: the plan of a new run of ``spec`` (or what is left of the run at ``resume``) as
    text, everything checked as a run would check it up to here; nothing is created or written."""
    if (spec is None) == (resume is None):
        raise TypeError("preview: give either a spec (a new run) or resume=RUN_DIRECTORY")
    run = None if resume is None else resumable(resume)
    spec = prepare(run.spec() if run is not None else spec)
    connect(executor, address, on_ray=protocol_of(spec).runs_on_ray, join=False)
    where = run.path if run is not None else new_run_path(spec, out=out, root=root)
    finished = run.finished() if run is not None else None
    return describe_plan(spec, where, estimate=estimate, root=root, finished=finished)


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
    log: str | None = None,
    on_start: Callable[[RunDir, Callable[[], None] | None], None] | None = None,
    **options: Any,
) -> tuple[RunDir, Summary]:
    """The one entry of a run: validate ``spec`` and create its run directory, or, with ``resume``,
    carry on the run there; run every unfinished trial and write the report (``options``: those of
    :func:`carry_on`).

    A Ray cluster the run needs is joined before the run directory is made, so a wrong address
    leaves nothing behind; what Ray logged goes to ``RUN/ray/ray.log``. ``log="tensorboard"`` also
    streams curves and returns to ``RUN/tensorboard``. ``on_start(run, flush)`` is called once the
    run directory exists (``flush`` writes what the log holds so far, or is None): a caller that may
    be interrupted learns where to tell the user to resume."""
    executor = options.get("executor", "local")
    check_executor(executor)  # before a run directory is created
    if log is not None and log not in LOGS:
        raise SpecError(f"log: unknown log {log!r}; choose one of {list(LOGS)}")
    if resume is not None:
        run, spec = open_run(resume=resume)
    else:
        spec = prepare(spec)
    ray_started = connect(
        executor,
        options.get("address"),
        on_ray=protocol_of(spec).runs_on_ray,
        verbose=options.get("verbose", False),
    )
    if resume is None:
        run = _create(spec, out, root)  # the spec validated above
        if progress:
            print(f"run directory: {run.path}", file=sys.stderr, flush=True)
    if ray_started:
        (run.path / "ray").mkdir(exist_ok=True)
        with open(run.path / "ray" / "ray.log", "a") as ray_log:
            ray_log.write(ray_started)
    logger = TensorBoardLog(run).start() if log == "tensorboard" else None
    if logger is not None:
        print(f"tensorboard: tensorboard --logdir {logger.folder}", file=sys.stderr)
    if on_start is not None:
        on_start(run, None if logger is None else logger.sync)
    summary = carry_on(run, spec, progress=progress, **options)
    if logger is not None:
        logger.stop()
    return run, summary


def resume(path: str | os.PathLike, **options: Any) -> tuple[RunDir, Summary]:
    """Carry on an interrupted run: ``run_experiment(resume=path, ...)``."""
    return run_experiment(resume=path, **options)


def report(path: str | os.PathLike) -> str:
    """Rebuild ``report.html`` of a run from its files; returns the report's path."""
    return build_report(RunDir(path))
