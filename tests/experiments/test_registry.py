"""Agents from the registry in every protocol: SAC from the command line, a user-registered agent,
per-environment defaults, and clear refusals."""

import numpy as np
import pandas as pd
import pytest

from contextrl.agents import (
    Agent,
    dqn,
    get_agent,
    ppo,
    register_agent,
    registered_agents,
    sac,
)
from contextrl.cli import main as cli_main
from contextrl.experiments import SpecError, parse_spec
from tests.helpers.report_tables import check_report, read_sections


def test_registry_lists_agents_and_refuses_mismatches():
    assert {"ppo", "dqn", "c51", "sac", "random"} <= set(registered_agents())
    with pytest.raises(KeyError, match="registered: "):
        get_agent("a2c")
    with pytest.raises(SpecError, match="unknown agent 'a2c'"):
        parse_spec({"protocol": "visibility", "agent": "a2c"})
    with pytest.raises(SpecError, match="acts in continuous action spaces; CartPole"):
        parse_spec({"protocol": "visibility", "agent": "sac"})
    with pytest.raises(SpecError, match="unknown c51 option"):
        parse_spec({"protocol": "visibility", "agent": "c51", "agent_options": {"lr": 1}})
    # C51 on CartPole starts from the paper's setting; the user's options override it
    c51 = get_agent("c51").config("CartPole", {"v_max": 200.0}, "concat_all")
    assert c51 == dqn.paper_config("CartPole", v_max=200.0, variant="concat_all")
    # where the paper has no setting: plain C51
    assert get_agent("c51").config("MountainCarContinuous", {}).distributional


def test_paper_settings_exist_only_for_registered_environments():
    import contextrl as crl

    assert set(dqn.PAPER_C51) <= set(crl.registered())
    assert set(sac.PAPER_SAC) <= set(crl.registered())


def test_user_registered_agent_runs_a_protocol_from_the_cli(tmp_path):
    register_agent(
        Agent(
            "tiny_ppo",
            ppo.PPOConfig,
            ppo.make_train,
            ppo.make_policy,
            defaults=lambda env: {"total_timesteps": 512, "num_steps": 32, "hidden_sizes": (8,)},
        ),
        replace=True,
    )
    out = tmp_path / "run"
    argv = ["run", "optimality_gap", "--agent", "tiny_ppo", "--seeds", "1", "--out", str(out)]
    argv += ["--set", "num_contexts=2", "--max-steps", "30", "--episodes", "1", "--quiet"]
    assert cli_main(argv) == 0
    curves = pd.concat(pd.read_parquet(p) for p in (out / "curves").glob("*.parquet"))
    assert curves["step"].max() == 512  # the registered defaults were used
    html = (out / "report.html").read_text()
    assert "Did the agents learn?" in html and "random policy: mean return" in html


def test_sac_runs_the_sensitivity_protocol_from_the_cli(tmp_path):
    out = tmp_path / "run"
    argv = ["run", "sensitivity", "--env", "Pendulum", "--agent", "sac", "--vary", "g"]
    argv += ["--set", "magnitudes=[0.5,1.0]", "--seeds", "1", "--timesteps", "300"]
    argv += ["--max-steps", "20", "--episodes", "1", "--out", str(out), "--quiet"]
    for option in ("learning_starts=100", "batch_size=16", "log_every=100", "hidden_sizes=[8]"):
        argv += ["--agent-option", option]
    assert cli_main(argv) == 0
    results = pd.read_parquet(next((out / "results").glob("*.parquet")))
    assert sorted(results["magnitude"]) == [0.5, 1.0]
    assert results["ctx.g"].tolist() == [10.0, 5.0]  # the shared default context, then A = 0.5
    assert (out / "checkpoints" / "default-hidden-s0.npz").exists()
    # Pendulum's dynamics are differentiable: the agent's return gradient comes beside the sweep
    training = pd.read_parquet(next((out / "training").glob("*.parquet")))
    assert np.isfinite(training[["gradient.g", "difference.g"]].to_numpy()).all()
    rows = read_sections(out / "report.html")["Return gradient"]["tables"]
    assert [r["feature"] for r in rows["Return gradient in A at the default context"]] == ["g"]
    assert check_report(out) > 0  # each value a direct computation from results and training
    spec = parse_spec({"protocol": "sensitivity", "env": "Pendulum", "agent": "sac"})
    # Pendulum is one of the paper's SAC environments: its setting is the base
    assert spec.agent_config("hidden") == sac.paper_config("Pendulum")


def test_sac_on_a_host_environment_runs_the_papers_visibility_setting(tmp_path):
    """`contextrl run visibility --env DmcWalker --agent sac --vary viscosity=...` at a tiny budget:
    training and evaluation through the host collector."""
    pytest.importorskip("dm_control")
    out = tmp_path / "run"
    argv = ["run", "visibility", "--env", "DmcWalker", "--agent", "sac"]
    argv += ["--vary", "viscosity=uniform:0:1", "--variants", "concat_varying", "--seeds", "1"]
    argv += ["--timesteps", "120", "--max-steps", "10", "--episodes", "1", "--quiet"]
    argv += ["--set", "num_train_contexts=2", "--set", "num_test_contexts=3", "--out", str(out)]
    for option in ("learning_starts=40", "batch_size=8", "log_every=40", "hidden_sizes=[8]"):
        argv += ["--agent-option", option]
    assert cli_main(argv) == 0
    results = pd.read_parquet(out / "results" / "chunk-0000.parquet")
    viscosity = results["ctx.viscosity"].to_numpy()
    assert len(results) == 3 and ((viscosity >= 0) & (viscosity <= 1)).all()
    assert results["return"].notna().all()
    curves = pd.read_parquet(out / "curves" / "chunk-0000.parquet")
    assert curves["step"].tolist() == [80, 120]  # 40 warm-up steps, then rows of 40
    assert (out / "checkpoints" / "visibility-concat_varying-s0.npz").exists()
    assert "Did the agents learn?" in (out / "report.html").read_text()
