"""`contextrl run hpo`: PB2 on a local Ray tunes PPO on sampled contexts; the best configuration feeds
another protocol through --agent-config."""

import pandas as pd
import pytest
import yaml

from contextrl.experiments import SpecError, parse_spec
from contextrl.experiments.commands import main as commands_main


def test_hpo_search_bounds_are_checked_before_anything_runs():
    with pytest.raises(SpecError, match="'lr' is not a ppo option"):
        parse_spec({"protocol": "hpo", "search": {"lr": [0.1, 0.2]}})
    with pytest.raises(SpecError, match="empty range"):
        parse_spec({"protocol": "hpo", "search": {"learning_rate": [0.1, 0.01]}})
    with pytest.raises(SpecError, match="gamma"):  # a bound that is no valid setting
        parse_spec({"protocol": "hpo", "search": {"gamma": [0.9, 1.5]}})
    with pytest.raises(SpecError, match="at least 2 members"):
        parse_spec({"protocol": "hpo", "population": 1})


def test_pb2_tunes_ppo_and_the_best_config_feeds_another_protocol(tmp_path):
    pytest.importorskip("ray")
    pytest.importorskip("GPy")
    out = tmp_path / "hpo"
    argv = ["run", "hpo", "--env", "CartPole", "--agent", "ppo", "--vary", "length=uniform:0.3:0.7"]
    argv += ["--agent-option", "num_steps=32", "--agent-option", "hidden_sizes=[8]"]
    argv += ["--set", "population=2", "--set", "rounds=3", "--set", "steps_per_round=256"]
    argv += ["--set", "num_train_contexts=4", "--set", "num_test_contexts=5", "--max-steps", "50"]
    argv += ["--episodes", "2", "--out", str(out), "--quiet"]
    assert commands_main(argv) == 0
    schedule = pd.read_parquet(out / "curves" / "chunk-0000.parquet")
    # two members, three rounds of 256 steps each, every hyper-parameter within its bounds
    assert sorted(schedule.groupby("trial")["step"].max()) == [768, 768]
    assert schedule["hp.learning_rate"].between(1e-5, 1e-2).all()
    assert schedule["hp.ent_coef"].between(0.0, 0.05).all()
    best = yaml.safe_load((out / "best.yaml").read_text())
    assert best["num_steps"] == 32 and 1e-5 <= best["learning_rate"] <= 1e-2
    results = pd.read_parquet(out / "results" / "chunk-0000.parquet")
    assert len(results) == 5 and results["ctx.length"].between(0.3, 0.7).all()
    assert results["hp.learning_rate"].iloc[0] == best["learning_rate"]
    html = (out / "report.html").read_text()
    assert "Hyper-parameter optimisation (PB2)" in html and 'data-figure="hpo-schedules"' in html
    # the best configuration as the agent of another protocol
    other = tmp_path / "visibility"
    argv = ["run", "visibility", "--agent-config", str(out / "best.yaml"), "--out", str(other)]
    argv += ["--max-chunks", "0", "--quiet"]
    assert commands_main(argv) == 0
    options = yaml.safe_load((other / "spec.yaml").read_text())["agent_options"]
    assert options == best
