"""A real interruption: `contextrl run` killed with SIGKILL in the middle of a chunk, then resumed, gives
the same results as an uninterrupted run, with no duplicate rows and no lost trial."""

import os
import signal
import subprocess
import sys
import time

import pandas as pd

from contextrl.experiments import expand, parse_spec, run_experiment

SPEC = {
    "protocol": "visibility",
    "env": "CartPole",
    "agent": "random",  # no training: the run's cost is evaluation, compiled once per process
    "variants": ["hidden"],
    "train": {"length": {"uniform": [0.25, 0.75]}},
    "num_train_contexts": 2,
    "num_test_contexts": 3,
    "seeds": 8,
    "batch_size": 1,  # 8 chunks of one trial each
    "max_steps": 500,
    "eval_episodes": 40,  # long enough chunks that the kill lands inside one
    "bootstrap_reps": 50,
}
CLI = [sys.executable, "-m", "contextrl.cli", "run"]
COLUMNS = ["trial", "context_index", "return"]


def cli_args(out) -> list[str]:
    return [
        *CLI,
        "visibility",
        "--out",
        str(out),
        "--quiet",
        "--agent",
        "random",
        "--vary",
        "length=uniform:0.25:0.75",
        "--seeds",
        "8",
        "--max-steps",
        "500",
        "--episodes",
        "40",
        "--set",
        "variants=[hidden]",
        "--set",
        "num_train_contexts=2",
        "--set",
        "num_test_contexts=3",
        "--set",
        "batch_size=1",
        "--set",
        "bootstrap_reps=50",
    ]


def test_sigkill_mid_chunk_then_resume_matches_an_uninterrupted_run(tmp_path):
    whole, _ = run_experiment(SPEC, out=tmp_path / "whole", progress=False, report=False)
    out = tmp_path / "killed"
    process = subprocess.Popen(cli_args(out), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    results = out / "results"
    deadline = time.monotonic() + 240
    while not (results.exists() and any(results.glob("chunk-*.parquet"))):
        assert process.poll() is None, process.stderr.read().decode()
        assert time.monotonic() < deadline, "the first chunk never finished"
        time.sleep(0.02)
    os.kill(process.pid, signal.SIGKILL)  # chunk 0 is written; chunk 1 is training now
    process.wait()
    finished = sorted(results.glob("chunk-*.parquet"))
    plan = expand(parse_spec(SPEC))
    assert 1 <= len(finished) < len(plan.chunks), "the kill must land before the run ended"
    resumed = subprocess.run(
        [*CLI, "--resume", str(out), "--quiet"], capture_output=True, text=True, timeout=600
    )
    assert resumed.returncode == 0, resumed.stderr
    killed = pd.concat(
        [pd.read_parquet(p) for p in sorted(results.glob("chunk-*.parquet"))], ignore_index=True
    )
    assert not killed.duplicated(["trial", "context_index"]).any()
    assert sorted(killed["trial"].unique()) == sorted(t.id for t in plan.trials)
    killed = killed.sort_values(["trial", "context_index"], ignore_index=True)
    pd.testing.assert_frame_equal(killed[COLUMNS], whole.results()[COLUMNS])
    assert not list(out.rglob("*.tmp"))  # no leftover partial file is ever read as a result
    assert (out / "report.html").exists()
