"""Executors run the unfinished chunks of a plan and write each one as soon as it is done.

``local`` trains chunk after chunk in this process (each chunk one vmapped, compiled call).
``processes`` runs one worker process per CPU core on this machine, each training whole chunks, so every
core is busy with its own chunk instead of sharing small operations with the others. ``ray``
sends chunks to a Ray cluster (``address``: an existing cluster, or None to start a local one that
listens on 127.0.0.1 only: :mod:`~contextrl.experiments.ray_cluster`); the workers rebuild the plan
from the spec, so only the spec and a chunk index travel. Either way a chunk that raises is recorded with its error and
traceback and the run goes on.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import functools
import io
import multiprocessing
import os
import queue
import re
import socket
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator

from tqdm import tqdm

from contextrl.compile_cache import use_compilation_cache
from contextrl.experiments.plan import Plan, expand
from contextrl.experiments.ray_cluster import start_ray
from contextrl.experiments.ray_output import ray_output_to
from contextrl.experiments.runs import RunDir, Summary
from contextrl.experiments.spec import SpecError, parse_spec, spec_to_dict
from contextrl.experiments.trials import run_chunk
from contextrl.xla_flags import xla_cpu_workaround

EXECUTORS = ("local", "processes", "ray")
BAR_REFRESH_SECONDS = 0.5  # how often worker executors redraw the bars of the chunks they run


class Progress:
    """One line per finished chunk: the run's chunks finished of all it has (``before``: finished by
    earlier calls), failures, elapsed time and an ETA for this call's chunks (``todo``)."""

    def __init__(self, plan: Plan, todo: list[int], before: int, enabled: bool = True):
        self.plan, self.todo, self.before = plan, len(todo), before
        self.stream, self.enabled = sys.stderr, enabled  # the stream of the time of the run
        self.done, self.failed, self.start = 0, 0, time.perf_counter()

    def __call__(self, chunk: int, ok: bool) -> None:
        self.done += 1
        self.failed += not ok
        if not self.enabled:
            return
        elapsed = time.perf_counter() - self.start
        eta = elapsed / self.done * (self.todo - self.done)
        trials = len(self.plan.chunks[chunk])
        status = "ok" if ok else "FAILED"
        finished = self.before + self.done
        tqdm.write(  # above any chunk bars on the terminal
            f"[{finished}/{len(self.plan.chunks)} chunks] chunk {chunk} ({trials} trials) {status}; "
            f"{self.failed} failed; elapsed {elapsed:.0f}s, eta {eta:.0f}s",
            file=self.stream,
        )


# An agent's progress line (agents.common.Progress): steps done / total, steps/s, recent return.
PROGRESS_LINE = re.compile(r"step\s+([\d,]+)/([\d,]+)\s+(\S+) steps/s\s+recent return\s+(\S+)")


class ProgressLines:
    """A stand-in for stdout while a chunk trains with the agents' progress lines on
    (``progress_every`` 1): each progress line becomes ``on_progress(done, total, recent_return)``;
    any other output passes on to the real stdout."""

    def __init__(self, on_progress: Callable[[int, int, str], None]):
        self.stdout = sys.stdout
        self.on_progress = on_progress
        self._pending = ""

    def write(self, text: str) -> int:
        self._pending += text
        *lines, self._pending = self._pending.split("\n")
        for line in lines:
            match = PROGRESS_LINE.search(line)
            if match is None:
                self.stdout.write(line + "\n")
                continue
            done, total = (int(group.replace(",", "")) for group in match.group(1, 2))
            self.on_progress(done, total, match.group(4))
        return len(text)

    def flush(self) -> None:
        self.stdout.flush()

    def close(self) -> None:
        if self._pending:
            self.write("\n")


class ChunkBar:
    """A bar for one chunk: its phase (compiling, training with steps done / total and the first
    trial's recent return, evaluating). Shown on a terminal only, as tqdm's bars are; ``position``
    stacks the bars of chunks that train at once in other processes."""

    def __init__(
        self,
        description: str,
        stream=None,
        disable: bool | None = None,
        position: int | None = None,
    ):
        self.bar = tqdm(
            desc=description,
            total=None,
            unit="step",
            unit_scale=True,
            file=stream or sys.stderr,
            disable=disable,
            leave=False,
            position=position,
            postfix="compiling",
        )

    def update(self, done: int, total: int, recent_return: str) -> None:
        if self.bar.total is None:  # training has begun: its rate starts now, not at compiling
            self.bar.reset(total=total)
        self.bar.update(done - self.bar.n)
        phase = "evaluating" if done >= total else "training"
        self.bar.set_postfix_str(f"{phase}, recent return {recent_return}")

    def close(self) -> None:
        self.bar.close()


def _describe(plan: Plan, chunk: int) -> str:
    trials = plan.chunks[chunk]
    return f"chunk {chunk} ({len(trials)} trials, {plan.trials[trials[0]].variant})"


def _watched_chunk(chunk_runner: Callable, plan: Plan, chunk: int, on_progress: Callable):
    """Run ``chunk`` with the agents' progress lines on, each one passed to ``on_progress(done,
    total, recent_return)``. Its results and checkpoints are those of the spec as given: the
    progress lines change no value, and the saved config is the spec's own."""
    spec = plan.spec
    trials = plan.chunks[chunk]
    watched = plan
    if spec.agent_entry().trained:
        options = {**spec.agent_options, "progress_every": 1}
        watched = dataclasses.replace(plan, spec=dataclasses.replace(spec, agent_options=options))
    lines = ProgressLines(on_progress)
    try:
        with contextlib.redirect_stdout(lines):
            result = chunk_runner(watched, trials)
    finally:
        lines.close()
    if result.checkpoint:
        result.checkpoint["config"] = spec.agent_config(plan.trials[trials[0]].variant)
    return result


def _chunk_with_bar(chunk_runner: Callable, plan: Plan, chunk: int):
    """Run ``chunk`` in this process under a :class:`ChunkBar` (on a terminal; elsewhere just run
    it)."""
    bar = ChunkBar(_describe(plan, chunk))
    try:
        if bar.bar.disable:
            return chunk_runner(plan, plan.chunks[chunk])
        return _watched_chunk(chunk_runner, plan, chunk, bar.update)
    finally:
        bar.close()


class ChunkBars:
    """The bars of chunks that train in worker processes (``processes``, ``ray``): each worker puts
    ``(chunk, done, total, recent_return)`` on a queue (``done`` None: compiling has begun) and the
    driver, between waits for finished chunks, draws them here, one bar per running chunk. Without
    a queue (``updates`` None: no bars) it draws nothing."""

    def __init__(self, plan: Plan, updates):
        self.plan, self.updates = plan, updates
        self.bars: dict[int, ChunkBar] = {}
        self.positions: dict[int, int] = {}

    def drain(self) -> None:
        while self.updates is not None:
            try:
                chunk, done, total, recent_return = self.updates.get_nowait()
            except queue.Empty:
                return
            if chunk not in self.bars:
                position = min(set(range(len(self.bars) + 1)) - set(self.positions.values()))
                self.positions[chunk] = position
                self.bars[chunk] = ChunkBar(
                    _describe(self.plan, chunk), disable=False, position=position
                )
            if done is not None:
                self.bars[chunk].update(done, total, recent_return)

    def finish(self, chunk: int) -> None:
        self.drain()
        if chunk in self.bars:
            self.bars.pop(chunk).close()
            del self.positions[chunk]

    def close(self) -> None:
        for chunk in list(self.bars):
            self.finish(chunk)


def _as_finished(pending: dict, wait: Callable, fetcher: Callable, bars: ChunkBars):
    """Yield ``(chunk, fetch)`` for each of the ``pending`` workers (handle -> chunk) as ``wait``
    returns it finished (``wait(handles)``: the finished ones, or none after a short timeout), with
    ``fetcher(handle)`` the call that returns its result or raises; the bars are redrawn between."""
    while pending:
        done = wait(list(pending))
        bars.drain()
        for handle in done:
            chunk = pending.pop(handle)
            bars.finish(chunk)
            yield chunk, fetcher(handle)


def _shows_bars(progress: bool) -> bool:
    """Whether worker executors draw chunk bars: with progress, on a terminal (as tqdm decides)."""
    return progress and sys.stderr.isatty()


def _pending(run: RunDir, plan: Plan, max_chunks: int | None) -> tuple[list[int], list[int]]:
    finished = run.finished()
    todo = [i for i in range(len(plan.chunks)) if i not in finished]
    if max_chunks is not None:
        todo = todo[:max_chunks]
    return todo, sorted(finished)


def _trial_ids(plan: Plan, chunk: int) -> list[str]:
    return [plan.trials[i].id for i in plan.chunks[chunk]]


def _settle(run: RunDir, plan: Plan, chunk: int, fetch: Callable, save_params: bool) -> bool:
    """Save a finished chunk's result, or record its failure (a failing trial must not kill the run);
    whether it succeeded."""
    try:
        result = fetch()
    except Exception as error:
        run.record_failure(chunk, _trial_ids(plan, chunk), repr(error), traceback.format_exc())
        return False
    run.save_chunk(chunk, result, _trial_ids(plan, chunk), save_params)
    return True


def _drive(
    run: RunDir,
    plan: Plan,
    max_chunks: int | None,
    progress: bool,
    save_params: bool,
    finished: Callable[[list[int]], Iterator[tuple[int, Callable]]],
) -> Summary:
    """What every executor does around its workers: pick the unfinished chunks, settle each one as
    ``finished(todo)`` yields it (its index and a call that returns its result or raises), report
    progress and summarise."""
    start = time.perf_counter()
    earlier = run.manifest().get("wall_seconds", 0.0)  # spent by earlier invocations
    todo, skipped = _pending(run, plan, max_chunks)
    report = Progress(plan, todo, len(skipped), enabled=progress)
    ran, failed = [], []
    for chunk, fetch in finished(todo):
        ok = _settle(run, plan, chunk, fetch, save_params)
        (ran if ok else failed).append(chunk)
        run.update_manifest(wall_seconds=earlier + time.perf_counter() - start)
        report(chunk, ok)
    remaining = sorted(set(range(len(plan.chunks))) - run.finished())
    return Summary(sorted(ran), skipped, sorted(failed), remaining, time.perf_counter() - start)


def run_local(
    run: RunDir,
    plan: Plan,
    *,
    max_chunks: int | None = None,
    progress: bool = True,
    save_params: bool = True,
    chunk_runner: Callable = run_chunk,
) -> Summary:
    """Run the unfinished chunks in this process, in plan order (with ``progress``, each under a
    :class:`ChunkBar`)."""

    def finished(todo: list[int]):
        for chunk in todo:
            if progress:
                yield chunk, functools.partial(_chunk_with_bar, chunk_runner, plan, chunk)
            else:
                yield chunk, functools.partial(chunk_runner, plan, plan.chunks[chunk])

    return _drive(run, plan, max_chunks, progress, save_params, finished)


def usable_cores() -> int:
    """The cores this process may run on (its affinity, which ``taskset`` narrows), as workers."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


PARENT_CHECK_SECONDS = 2.0


def _exit_with_parent(parent: int) -> None:
    """A worker's initializer: end the worker when the process that started it is gone.

    A parent killed outright (SIGTERM, SIGKILL, a scheduler's time limit) cannot shut its pool down,
    and its workers would otherwise train their chunks for hours with nobody left to keep them."""

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_CHECK_SECONDS)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def run_processes(
    run: RunDir,
    plan: Plan,
    *,
    workers: int | None = None,
    max_chunks: int | None = None,
    progress: bool = True,
    save_params: bool = True,
) -> Summary:
    """Run the unfinished chunks on ``workers`` local processes (default: one per CPU core).

    Each worker compiles once per chunk shape and keeps training chunks; results are written here, in
    the order they finish. Workers are spawned, so a script that calls this needs the usual
    ``if __name__ == "__main__":`` guard.
    """
    spec_data = spec_to_dict(plan.spec)

    def finished(todo: list[int]):
        count = max(1, min(workers or usable_cores(), len(todo)))
        context = multiprocessing.get_context("spawn")  # a fresh JAX in each worker, never a fork
        with contextlib.ExitStack() as stack:
            updates = None
            if _shows_bars(progress):
                updates = stack.enter_context(context.Manager()).Queue()
            bars = stack.enter_context(contextlib.closing(ChunkBars(plan, updates)))
            pool = stack.enter_context(
                concurrent.futures.ProcessPoolExecutor(
                    count,
                    mp_context=context,
                    initializer=_exit_with_parent,
                    initargs=(os.getpid(),),
                )
            )
            pending = {pool.submit(_remote_chunk, spec_data, c, updates): c for c in todo}

            def wait(futures):
                return concurrent.futures.wait(
                    futures, timeout=BAR_REFRESH_SECONDS, return_when="FIRST_COMPLETED"
                )[0]

            yield from _as_finished(pending, wait, lambda future: future.result, bars)

    return _drive(run, plan, max_chunks, progress, save_params, finished)


def connect(
    executor: str,
    address: str | None,
    on_ray: bool = False,
    join: bool = True,
    verbose: bool = False,
) -> str:
    """Check the executor before a run directory exists: for ``ray`` (or a protocol that runs on Ray
    itself, ``on_ray``), join (or start) the cluster now, so a wrong ``--address`` is a one-line
    error and leaves nothing half made. ``join`` off (a dry run, planned before a cluster may be
    up): the executor and ``address`` are checked, no cluster is joined or started.

    Returns what Ray logged while starting, for the run's ``ray/ray.log`` (with ``verbose`` it is
    shown on the terminal instead and "" is returned)."""
    if executor not in EXECUTORS:
        raise SpecError(f"executor: unknown executor {executor!r}; choose one of {list(EXECUTORS)}")
    if executor != "ray" and not on_ray:
        if address is not None:
            raise SpecError(
                f"--address {address}: only --executor ray and the hpo protocol use a Ray cluster"
            )
        return ""
    if not join:
        return ""
    import ray  # optional and slow to import: only a Ray run loads it

    if ray.is_initialized():
        return ""
    _refuse_a_silent_address(address)
    started = io.StringIO()
    try:
        with contextlib.nullcontext() if verbose else ray_output_to(started):
            start_ray(address)
    except ConnectionError as error:
        where = f"--address {address}" if address else "a local Ray cluster"
        reason = str(error).split(". ")[0]
        raise SpecError(
            f"{where}: {reason}; start a cluster with `ray start --head`, or leave out --address "
            "to start a local one"
        ) from None
    return started.getvalue()


def _refuse_a_silent_address(address: str | None, timeout: float = 5.0) -> None:
    """A cluster address ``host:port`` where nothing accepts a connection is refused at once, in one
    line (``ray.init`` would keep retrying it). ``auto``, ``local`` and ``ray://`` are Ray's."""
    host, _, port = (address or "").rpartition(":")
    if not host or not port.isdigit() or "://" in address:
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as error:
        raise SpecError(
            f"--address {address}: no Ray cluster answers there ({error.strerror or error}); start "
            "one with `ray start --head`, or leave out --address to start a local one"
        ) from None


def _remote_chunk(spec_data: dict, chunk: int, updates=None):
    """What a worker (Ray's or a local process) runs: rebuild the plan from the spec, run one chunk;
    with a queue of ``updates``, report its progress there (see :class:`ChunkBars`)."""
    xla_cpu_workaround()  # a fresh worker: before its first JAX computation
    use_compilation_cache()  # workers load what another worker or an earlier run compiled
    plan = expand(parse_spec(spec_data))
    if updates is None:
        return run_chunk(plan, plan.chunks[chunk])
    updates.put((chunk, None, None, None))

    def report(done: int, total: int, recent_return: str) -> None:
        updates.put((chunk, done, total, recent_return))

    return _watched_chunk(run_chunk, plan, chunk, report)


def run_ray(
    run: RunDir,
    plan: Plan,
    *,
    address: str | None = None,
    max_chunks: int | None = None,
    progress: bool = True,
    save_params: bool = True,
    cpus_per_chunk: float = 1.0,
) -> Summary:
    """Spread the unfinished chunks over a Ray cluster; results are written here as they arrive."""
    import ray  # optional and slow to import: only a Ray run loads it

    if not ray.is_initialized():
        start_ray(address)
    remote = ray.remote(num_cpus=cpus_per_chunk, max_retries=0)(_remote_chunk)
    spec_data = spec_to_dict(plan.spec)

    def finished(todo: list[int]):
        updates = None
        if _shows_bars(progress):
            from ray.util.queue import Queue

            updates = Queue(actor_options={"num_cpus": 0})
        pending = {remote.remote(spec_data, chunk, updates): chunk for chunk in todo}

        def wait(refs):
            return ray.wait(refs, num_returns=1, timeout=BAR_REFRESH_SECONDS)[0]

        with contextlib.closing(ChunkBars(plan, updates)) as bars:
            yield from _as_finished(
                pending, wait, lambda ref: functools.partial(ray.get, ref), bars
            )
        if updates is not None:
            updates.shutdown()

    return _drive(run, plan, max_chunks, progress, save_params, finished)


def run_chunks(
    run: RunDir,
    plan: Plan,
    *,
    executor: str = "local",
    address: str | None = None,
    max_chunks: int | None = None,
    progress: bool = True,
    save_params: bool = True,
) -> Summary:
    """Run the plan's unfinished chunks with the named executor."""
    if executor == "ray":
        return run_ray(
            run,
            plan,
            address=address,
            max_chunks=max_chunks,
            progress=progress,
            save_params=save_params,
        )
    if executor == "processes":
        return run_processes(
            run, plan, max_chunks=max_chunks, progress=progress, save_params=save_params
        )
    if executor == "local":
        return run_local(
            run, plan, max_chunks=max_chunks, progress=progress, save_params=save_params
        )
    raise SpecError(f"executor: unknown executor {executor!r}; choose one of {list(EXECUTORS)}")
