"""Protocols with the real PPO agent (tiny budget), the Ray executor and the command line."""

import numpy as np
import pandas as pd
import pytest

from contextrl.analysis.scores import gap_statistics
from contextrl.cli import main as cli_main
from contextrl.experiments import executors, expand, run_experiment
from contextrl.experiments.reports import run_cells

PPO_OPTIONS = {"total_timesteps": 2048, "num_envs": 4, "num_steps": 64, "hidden_sizes": [16, 16]}


def test_optimality_gap_with_ppo_trains_general_and_specialists(tmp_path):
    """Also: worker processes train exactly what this process trains (trained agents, not a random
    policy), and the report states the gap, and each seed's return, that gap_statistics computes."""
    spec = {
        "protocol": "optimality_gap",
        "num_contexts": 2,
        "seeds": 2,
        "variants": ["concat_varying"],
        "agent_options": PPO_OPTIONS,
        "max_steps": 100,
        "eval_episodes": 2,
        "bootstrap_reps": 100,
    }
    run, summary = run_experiment(spec, out=tmp_path / "run", progress=False)
    assert summary.failed == []
    results = run.results()
    assert set(results["kind"]) == {"general", "specialist"}
    assert len(results) == 2 * 2 + 2 * 2  # general: 2 seeds x 2 contexts; 2 specialists x 2 seeds
    checkpoints = sorted(p.stem for p in (run.path / "checkpoints").glob("*.npz"))
    assert checkpoints == sorted(results["trial"].unique())
    curves = run.curves()
    assert set(curves["trial"]) == set(results["trial"]) and curves["step"].max() == 2048
    html = (run.path / "report.html").read_text()
    assert "Optimality gap (concat_varying)" in html and "Probability that a specialist" in html
    parsed = run.spec()
    cells = run_cells(run, expand(parsed), results)
    stats = gap_statistics(cells, parsed.variants, **parsed.design)
    assert f"= {stats['concat_varying'].gap}." in html
    general = stats["concat_varying"].per_seed()["general"]
    assert len(general) == 2 and "general " + ", ".join(f"{v:.1f}" for v in general) in html
    spread, summary = run_experiment(
        spec, out=tmp_path / "spread", executor="processes", progress=False, report=False
    )
    assert summary.failed == []
    columns = ["trial", "context_index", "return"]
    pd.testing.assert_frame_equal(
        spread.results()[columns].sort_values(columns[:2], ignore_index=True),
        results[columns].sort_values(columns[:2], ignore_index=True),
    )


@pytest.mark.slow  # a local Ray session; Ray's address rule: test_ray_loopback.py
def test_ray_executor_matches_local(tmp_path, monkeypatch, capsys):
    """Same rows as here; each chunk's bar (reported by the Ray worker through a queue) is shown;
    the lines Ray prints while it starts are returned for the run's log, not shown."""
    ray = pytest.importorskip("ray")
    spec = {
        "protocol": "visibility",
        "agent": "random",
        "variants": ["hidden"],
        "seeds": 3,
        "batch_size": 1,
        "num_train_contexts": 2,
        "num_test_contexts": 3,
        "max_steps": 20,
        "eval_episodes": 2,
    }
    local, _ = run_experiment(spec, out=tmp_path / "local", progress=False, report=False)
    started = executors.connect("ray", None)  # as `contextrl run --executor ray` starts Ray
    assert "Started a local Ray instance" in started  # kept for the run's ray/ray.log
    monkeypatch.setattr(executors, "_shows_bars", lambda progress: progress)  # as on a terminal
    capsys.readouterr()
    try:
        remote, summary = run_experiment(spec, out=tmp_path / "ray", executor="ray", report=False)
    finally:
        ray.shutdown()
    assert sorted(summary.ran) == [0, 1, 2] and summary.failed == []
    shown = capsys.readouterr().err
    assert all(f"chunk {chunk} (1 trials, hidden)" in shown for chunk in range(3)), shown
    columns = ["trial", "context_index", "return"]
    pd.testing.assert_frame_equal(remote.results()[columns], local.results()[columns])


def test_cli_run_report_and_resume(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["run", "visibility", "--agent", "random", "--variants", "hidden", "--seeds", "2"]
    argv += ["--vary", "length=uniform:0.3:0.6", "--test", "length=uniform:0.1:1.0"]
    argv += [
        "--set",
        "num_train_contexts=2",
        "--set",
        "num_test_contexts=3",
        "--set",
        "batch_size=1",
    ]
    argv += [
        "--max-steps",
        "20",
        "--episodes",
        "1",
        "--out",
        str(out),
        "--quiet",
        "--max-chunks",
        "1",
    ]
    assert cli_main(argv) == 0
    assert "contextrl run --resume" in capsys.readouterr().out
    assert cli_main(["run", "--resume", str(out), "--quiet"]) == 0
    results = pd.read_parquet(out / "results" / "chunk-0001.parquet")
    lengths = results["ctx.length"].to_numpy()
    assert np.all((lengths >= 0.1) & (lengths <= 1.0))
    (out / "report.html").unlink()
    assert cli_main(["report", str(out)]) == 0
    assert (out / "report.html").exists()


def test_cli_refuses_bad_input_with_one_line(tmp_path, capsys):
    assert cli_main(["run", "visibility", "--env", "Nope", "--root", str(tmp_path)]) == 2
    assert "unknown environment 'Nope'" in capsys.readouterr().err
    assert cli_main(["run", "sensitivity", "--vary", "wheels", "--root", str(tmp_path)]) == 2
    assert "wheels" in capsys.readouterr().err
    assert cli_main(["report", str(tmp_path / "missing")]) == 2
    assert not list(tmp_path.iterdir())
