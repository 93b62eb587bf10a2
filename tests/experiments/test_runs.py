"""Whole protocols on a tiny budget: run directories, reports, resume, failures, atomic writes."""

import contextlib
import io
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from contextrl.agents.common import Progress
from contextrl.analysis import plots
from contextrl.experiments import RunDir, executors, expand, report, resume, run_experiment
from contextrl.experiments.executors import ChunkBar, ProgressLines, run_local
from contextrl.experiments.runs import atomic_write
from contextrl.experiments.trials import run_chunk

TINY = {"agent": "random", "max_steps": 20, "eval_episodes": 2, "bootstrap_reps": 100}


def sections(run: RunDir) -> list[str]:
    html = (run.path / "report.html").read_text()
    return [part.split("</h2>")[0] for part in html.split("<h2>")[1:]]


# Every protocol's report on Pendulum, whose returns are all negative (heat-map scale, near-best fraction)
PENDULUM = {"env": "Pendulum", "train": {"l": {"uniform": [0.5, 1.5]}}}
PROTOCOLS = [
    (
        {
            "protocol": "sensitivity",
            "env": "Pendulum",
            "features": ["l", "g"],
            "magnitudes": [0.5, 1, 2],
        },
        ["Summary", "Environment", "Sensitivity", "Spec", "Run metadata"],
        {"sensitivity-ecdf", "sensitivity-l", "sensitivity-g"},
    ),
    (
        {"protocol": "optimality_gap", "num_contexts": 3, **PENDULUM},
        [
            "Summary",
            "Environment",
            "Optimality gap (hidden)",
            "Test return per context",
            "Spec",
            "Run metadata",
        ],
        {
            "optgap-ecdf-hidden",
            "optgap-intervals-hidden",
            "optgap-per-context-hidden",
            "return-vs-l",
        },
    ),
    (
        {"protocol": "visibility", "num_train_contexts": 3, "num_test_contexts": 4, **PENDULUM},
        [
            "Summary",
            "Environment",
            "Context visibility",
            "Test return per context",
            "Spec",
            "Run metadata",
        ],
        {"test-ecdf", "test-histogram", "test-intervals", "return-vs-l"},
    ),
    (
        {
            "protocol": "train_test",
            "env": "Pendulum",
            "train_box": {"l": [0.5, 1.0], "g": [8.0, 12.0]},
            "test_box": {"l": [0.2, 1.5], "g": [4.0, 16.0]},
            "modes": ["A", "C"],
            "variants": ["hidden"],
            "num_test_contexts": 16,
        },
        [
            "Summary",
            "Environment",
            "Train/test modes",
            "Test return per context",
            "Spec",
            "Run metadata",
        ],
        {"heatmap-A-hidden", "heatmap-C-hidden", "return-vs-l", "return-vs-g"},
    ),
    (
        {"protocol": "tabular", "num_random": 2},
        ["Summary", "Tabular cMDPs", "Spec", "Run metadata"],
        {"tabular-gaps"},
    ),
]


@pytest.mark.parametrize(("data", "expected_sections", "expected_figures"), PROTOCOLS)
def test_every_protocol_runs_end_to_end(
    data, expected_sections, expected_figures, tmp_path, monkeypatch
):
    spec = {**TINY, "seeds": 2, **data} if data["protocol"] != "tabular" else data
    heatmaps = []  # each heatmap's title and the training contexts it marks
    draw = plots.heatmap
    monkeypatch.setattr(
        plots,
        "heatmap",
        lambda *a, **k: heatmaps.append((k["title"], k.get("train_points"))) or draw(*a, **k),
    )
    run, summary = run_experiment(spec, out=tmp_path / "run", progress=False)
    assert summary.failed == [] and summary.remaining == []
    assert sections(run) == expected_sections
    figures = {p.stem for p in (run.path / "figures").glob("*.png")}
    assert expected_figures <= figures
    results = run.results()
    assert not results.empty and np.all(np.isfinite(results["return"]))
    if data["protocol"] != "tabular":
        assert results["return"].max() < 0
    if data["protocol"] == "sensitivity":
        # 2 seeds x (the default context once + 2 features x the 2 magnitudes other than 1)
        assert len(results) == 2 * 5
        assert set(results["feature"]) == {"(default)", "l", "g"}
    if data["protocol"] == "optimality_gap":
        html = (run.path / "report.html").read_text()
        fractions = re.search(r"general (\d\.\d\d), specialists (\d\.\d\d)", html).groups()
        assert max(map(float, fractions)) > 0  # someone reaches the best return, though negative
    if data["protocol"] == "train_test":
        # the red dots are each mode's training contexts (they once were the test contexts)
        plan = expand(run.spec())
        assert [title for title, _ in heatmaps] == ["mode A, hidden", "mode C, hidden"]
        for (_, marked), mode in zip(heatmaps, ["A", "C"], strict=True):
            train = plan.sets[f"train-{mode}"].contexts
            np.testing.assert_allclose(marked, np.stack([train.l, train.g], axis=1))
    if data["protocol"] == "tabular":
        gaps = results.groupby("trial").apply(
            lambda g: (g["optimal_return"] - g["oblivious_return"]).mean(), include_groups=False
        )
        assert gaps["paper 3-state cMDP"] == pytest.approx(3.0)


def test_sensitivity_returns_change_with_the_context(tmp_path):
    spec = {**TINY, "max_steps": 200, "eval_episodes": 20, "seeds": 1, "protocol": "sensitivity"}
    spec.update(features=["length"], magnitudes=[0.1, 4.0])
    run, _ = run_experiment(spec, out=tmp_path / "run", progress=False, report=False)
    by_magnitude = run.results().groupby("magnitude")["return"].mean()
    # a random policy keeps a 10x longer pole (slower to fall) up much longer
    assert by_magnitude[4.0] > 1.5 * by_magnitude[0.1]


VISIBILITY = {**TINY, "protocol": "visibility", "seeds": 4, "batch_size": 1, "variants": ["hidden"]}
VISIBILITY.update(num_train_contexts=2, num_test_contexts=3)


def test_interrupted_run_resumes_to_the_same_results(tmp_path):
    whole, _ = run_experiment(VISIBILITY, out=tmp_path / "whole", progress=False, report=False)
    part, summary = run_experiment(
        VISIBILITY, out=tmp_path / "part", progress=False, report=False, max_chunks=2
    )
    assert summary.ran == [0, 1] and summary.remaining == [2, 3]
    first = (part.path / "results" / "chunk-0000.parquet").read_bytes()
    resumed, summary = resume(part.path, progress=False)
    assert summary.skipped == [0, 1] and summary.ran == [2, 3]
    assert (part.path / "results" / "chunk-0000.parquet").read_bytes() == first  # not redone
    columns = ["trial", "context_index", "return"]
    pd.testing.assert_frame_equal(resumed.results()[columns], whole.results()[columns])
    assert (part.path / "report.html").exists()


def test_worker_processes_give_the_results_of_this_process(tmp_path, monkeypatch, capsys):
    """The processes executor spreads chunks over worker processes: same rows, none lost or doubled;
    on a terminal each chunk's bar is drawn from what its worker reports through the queue."""
    here, _ = run_experiment(VISIBILITY, out=tmp_path / "here", progress=False, report=False)
    monkeypatch.setattr(executors, "_shows_bars", lambda progress: progress)  # as on a terminal
    capsys.readouterr()
    spread, summary = run_experiment(
        VISIBILITY, out=tmp_path / "spread", executor="processes", report=False
    )
    assert summary.ran == [0, 1, 2, 3] and summary.failed == []
    shown = capsys.readouterr().err
    assert all(f"chunk {chunk} (1 trials, hidden)" in shown for chunk in range(4)), shown
    columns = ["trial", "context_index", "return"]
    ordered = spread.results()[columns].sort_values(columns[:2], ignore_index=True)
    pd.testing.assert_frame_equal(
        ordered, here.results()[columns].sort_values(columns[:2], ignore_index=True)
    )


# A parent that starts a worker as the processes executor does, prints the worker's process id and
# waits (the worker sleeps as a long chunk would).
ORPHAN_PARENT = """
import concurrent.futures, multiprocessing, os, time
from contextrl.experiments import executors
if __name__ == "__main__":
    pool = concurrent.futures.ProcessPoolExecutor(
        1, mp_context=multiprocessing.get_context("spawn"),
        initializer=executors._exit_with_parent, initargs=(os.getpid(),))
    print(pool.submit(os.getpid).result(), flush=True)
    pool.submit(time.sleep, 600)
    time.sleep(600)
"""


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie (an orphan's state until it is reaped)."""
    stat = Path(f"/proc/{pid}/stat")
    try:
        return stat.read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc (Linux)")
def test_worker_processes_end_when_their_parent_is_killed():
    """A run killed outright cannot shut its pool down: its workers notice and end instead of
    training their chunks for nobody."""
    parent = subprocess.Popen(
        [sys.executable, "-c", ORPHAN_PARENT], stdout=subprocess.PIPE, text=True
    )
    worker = int(parent.stdout.readline())
    assert _running(worker)
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 10 * executors.PARENT_CHECK_SECONDS
    while _running(worker) and time.monotonic() < deadline:
        time.sleep(0.2)
    if _running(worker):
        os.kill(worker, signal.SIGKILL)
        pytest.fail(f"worker {worker} still running after its parent was killed")


def test_failed_chunk_is_recorded_and_retried_on_resume(tmp_path):
    run, _ = run_experiment(VISIBILITY, out=tmp_path / "run", progress=False, max_chunks=0)
    plan = expand(run.spec())

    def flaky(plan_, chunk):
        if chunk == plan_.chunks[1]:
            raise RuntimeError("simulated out-of-memory")
        return run_chunk(plan_, chunk)

    summary = run_local(run, plan, progress=False, chunk_runner=flaky)
    assert summary.failed == [1] and summary.ran == [0, 2, 3]
    (failure,) = run.failures()
    assert "simulated out-of-memory" in failure["error"]
    assert failure["trials"] == [plan.trials[plan.chunks[1][0]].id]
    report(run.path)
    assert "Failures" in sections(run)
    # the run keeps the time spent on it after every chunk: a later invocation adds to it
    spent = run.manifest()["wall_seconds"]
    assert spent >= sum(run.timings().values()) > 0
    _, summary = resume(run.path, progress=False)
    assert summary.ran == [1] and run.failures() == []
    assert run.manifest()["wall_seconds"] >= spent + run.timings()["1"]
    assert "Failures" not in sections(run)


def test_atomic_writes_leave_no_partial_results(tmp_path):
    run, _ = run_experiment(VISIBILITY, out=tmp_path / "run", progress=False, max_chunks=1)
    # a crash while writing leaves a temporary file that never counts as a finished chunk
    (run.path / "results" / ".chunk-0001.parquet.123.tmp").write_bytes(b"PAR1 half")
    assert run.finished() == {0}

    def crash(temporary):
        with open(temporary, "wb") as handle:
            handle.write(b"half")
        raise KeyboardInterrupt

    target = run.path / "results" / "chunk-0002.parquet"
    with pytest.raises(KeyboardInterrupt):
        atomic_write(target, crash)
    assert not target.exists() and run.finished() == {0}


def test_existing_run_directory_is_not_overwritten(tmp_path):
    run_experiment({"protocol": "tabular", "num_random": 0}, out=tmp_path / "run", progress=False)
    with pytest.raises(FileExistsError, match="--resume"):
        run_experiment({"protocol": "tabular"}, out=tmp_path / "run", progress=False)
    spec = json.loads((tmp_path / "run" / "manifest.json").read_text())
    assert "versions" in spec and "jax" in spec["versions"]


def test_chunk_bar_reads_the_agents_progress_lines_into_its_phase(capsys):
    """The bar takes the agents' progress lines (steps done / total, recent return) as its phase;
    any other output passes on."""
    shown = io.StringIO()
    bar = ChunkBar("chunk 0 (2 trials, hidden)", shown, disable=False)
    assert "compiling" in shown.getvalue()
    progress = Progress("PPO", 200, every=1)
    lines = ProgressLines(bar.update)
    with contextlib.redirect_stdout(lines):
        progress(0, 100, np.array([12.0]))
        progress(1, 150, np.array([20.5]))
        print("an agent's warning")
    assert (bar.bar.n, bar.bar.total) == (150, 200)
    assert "training, recent return 20.50" in shown.getvalue()
    with contextlib.redirect_stdout(lines):
        progress(2, 200, np.array([30.0]))
    assert "evaluating, recent return 30.00" in shown.getvalue()
    lines.close()
    bar.close()
    assert capsys.readouterr().out == "an agent's warning\n"
