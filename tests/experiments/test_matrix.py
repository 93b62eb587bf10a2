"""Every protocol with every registered agent, on a JAX and a host environment, through the
``contextrl`` command at a tiny budget; meaningless combinations are refused with one clear line.

The full cross product (5 protocols × 5 agents × 2 kinds of environment) would train 50 times, so
each (protocol, agent) pair runs once, on one kind of environment, chosen so that every protocol and
every agent runs on both kinds (here or in the tests named below) while few runs compile a JAX
training loop (the costly part; a host run compiles only the agent's update). Pairs that other tests
already run through the command line are not repeated: sensitivity × sac on Pendulum and visibility ×
sac on DmcWalker (test_registry.py), optimality_gap × a PPO agent (test_registry.py), visibility ×
random (test_agents.py), hpo × ppo (test_hpo.py, which also checks that host training continues a
member's parameters). hpo × c51
is not run: C51 is DQN's distributional head (agents/dqn.py), and a PB2 run costs a Ray session; PB2
runs DQN here on JAX and SAC on a host environment.

    protocol        ppo          dqn          c51          sac                random
    sensitivity     host         host         host         (JAX, elsewhere)   host
    optimality_gap  (JAX, else.) host         host         host               host
    visibility      JAX          host         JAX          (host, elsewhere)  (JAX, elsewhere)
    train_test      host         JAX          host         host               host
    hpo             (JAX, else.) JAX          (as dqn)     host               refused
    tabular with an agent or environment: refused.

Discrete agents take CartPole (JAX) or LunarLander (host, Box2D); continuous ones Pendulum or
LunarLanderContinuous. Each run checks its results table (rows, contexts within the asked ranges,
finite returns), its report's sections and, for trained agents, the saved agent.
"""

import numpy as np
import pandas as pd
import pytest
import yaml

from contextrl.cli import main as contextrl
from tests.helpers.report_tables import check_report, read_sections

# Smallest budgets that still train and update each agent a few times.
OPTIONS = {
    "ppo": {"total_timesteps": 128, "num_envs": 2, "num_steps": 32, "num_minibatches": 2},
    "dqn": {"total_timesteps": 128, "num_envs": 2, "learning_starts": 32, "batch_size": 8},
    "sac": {"total_timesteps": 64, "learning_starts": 32, "batch_size": 8},
    "random": {},
}
OPTIONS["c51"] = OPTIONS["dqn"]
COMMON = {"update_epochs": 1, "buffer_size": 256, "log_every": 32, "target_update_interval": 16}

# Per environment: a feature to vary, its training range, and a second feature (train/test box).
FEATURES = {
    "CartPole": (("length", 0.3, 0.7), ("gravity", 8.0, 12.0)),
    "Pendulum": (("l", 0.6, 1.4), ("g", 8.0, 12.0)),
    "LunarLander": (("GRAVITY_Y", -12.0, -8.0), ("MAIN_ENGINE_POWER", 10.0, 16.0)),
}
FEATURES["LunarLanderContinuous"] = FEATURES["LunarLander"]

SECTIONS = {
    "sensitivity": "Sensitivity",
    "optimality_gap": "Optimality gap (hidden)",
    "visibility": "Context visibility",
    "train_test": "Train/test modes",
    "hpo": "Hyper-parameter optimisation (PB2)",
}

CASES = [
    ("sensitivity", "ppo", "LunarLander"),
    ("sensitivity", "dqn", "LunarLander"),
    ("sensitivity", "c51", "LunarLander"),
    ("sensitivity", "random", "LunarLanderContinuous"),
    ("optimality_gap", "dqn", "LunarLander"),
    ("optimality_gap", "c51", "LunarLander"),
    ("optimality_gap", "sac", "LunarLanderContinuous"),
    ("optimality_gap", "random", "LunarLander"),
    ("visibility", "ppo", "Pendulum"),
    ("visibility", "dqn", "LunarLander"),
    ("visibility", "c51", "CartPole"),
    ("train_test", "ppo", "LunarLanderContinuous"),
    ("train_test", "dqn", "CartPole"),
    ("train_test", "c51", "LunarLander"),
    ("train_test", "sac", "LunarLanderContinuous"),
    ("train_test", "random", "LunarLander"),
    ("hpo", "dqn", "CartPole"),
    ("hpo", "sac", "LunarLanderContinuous"),
]
# PB2 starts a local Ray session (about a minute on two cores): in `make test-slow`.
SLOW = {"hpo"}


pytestmark = pytest.mark.usefixtures("shut_down_ray")  # conftest.py


def agent_options(agent: str, protocol: str) -> list[str]:
    from contextrl.agents import get_agent

    entry = get_agent(agent)
    valid = set(entry.option_names())
    options = {**OPTIONS[agent], **{k: v for k, v in COMMON.items() if k in valid}}
    if protocol == "hpo":  # its budget is rounds × steps_per_round (protocol_args)
        del options["total_timesteps"]
    if entry.trained:
        options["hidden_sizes"] = [8]
    return [item for k, v in options.items() for item in ("--agent-option", f"{k}={v}")]


def protocol_args(protocol: str, agent: str, env: str) -> tuple[list[str], int]:
    """The protocol's own options and how many test contexts its results table holds."""
    (first, low, high), (second, low2, high2) = FEATURES[env]
    if protocol == "sensitivity":
        return ["--vary", first, "--set", "magnitudes=[0.5,1.0,2.0]"], 3
    if protocol == "optimality_gap":  # a general agent on 2 contexts + one specialist per context
        return ["--vary", f"{first}=uniform:{low}:{high}", "--set", "num_contexts=2"], 2 + 2
    if protocol == "visibility":
        sets = ["--set", "num_train_contexts=2", "--set", "num_test_contexts=3"]
        return ["--vary", f"{first}=uniform:{low}:{high}", *sets], 3
    if protocol == "train_test":  # mode A: the 2 x 2 test grid over a box twice the training box
        width, width2 = high - low, high2 - low2
        test_box = {first: [low - width / 2, high + width / 2]}
        test_box[second] = [low2 - width2 / 2, high2 + width2 / 2]
        return [
            *("--vary", f"{first}=[{low},{high}]", "--vary", f"{second}=[{low2},{high2}]"),
            *("--set", f"test_box={test_box}", "--set", "modes=[A]"),
            *("--set", "num_train_contexts=2", "--set", "num_test_contexts=4"),
        ], 4
    # hpo: two members, one round of the agent's own training budget
    steps = OPTIONS[agent]["total_timesteps"]
    return [
        *("--vary", f"{first}=uniform:{low}:{high}", "--set", "population=2"),
        *("--set", "rounds=1", "--set", f"steps_per_round={steps}"),
        *("--set", "num_train_contexts=2", "--set", "num_test_contexts=3"),
    ], 3


def results(out) -> pd.DataFrame:
    return pd.concat(
        [pd.read_parquet(p) for p in sorted((out / "results").glob("*.parquet"))],
        ignore_index=True,
    )


@pytest.mark.parametrize(
    ("protocol", "agent", "env"),
    [pytest.param(*c, marks=[pytest.mark.slow] if c[0] in SLOW else []) for c in CASES],
    ids=["-".join(c) for c in CASES],
)
def test_protocol_runs_with_agent_from_the_command_line(protocol, agent, env, tmp_path, capsys):
    if protocol == "hpo":
        pytest.importorskip("ray")
    out = tmp_path / "run"
    own, rows = protocol_args(protocol, agent, env)
    argv = ["run", protocol, "--env", env, "--agent", agent, "--variants", "hidden"]
    argv += [] if protocol == "hpo" else ["--seeds", "1"]  # hpo trains a population instead
    argv += ["--max-steps", "10", "--episodes", "1", "--out", str(out), "--quiet"]
    assert contextrl([*argv, *own, *agent_options(agent, protocol)]) == 0
    table = results(out)
    assert len(table) == rows and np.isfinite(table["return"]).all()
    (first, low, high), (second, low2, high2) = FEATURES[env]
    values = table[f"ctx.{first}"]
    if protocol == "sensitivity":
        default = values[table["magnitude"] == 1.0].iloc[0]
        assert sorted(table["magnitude"]) == [0.5, 1.0, 2.0]
        np.testing.assert_allclose(sorted(values / default), [0.5, 1.0, 2.0], rtol=1e-5)
    elif protocol == "train_test":  # the test grid spans the test box, corners included
        width = high - low
        np.testing.assert_allclose(sorted(set(values)), [low - width / 2, high + width / 2])
    else:
        assert values.between(low, high).all()
    if protocol == "optimality_gap":
        assert sorted(table.groupby("kind")["trial"].nunique().items()) == [
            ("general", 1),
            ("specialist", 2),
        ]
    html = (out / "report.html").read_text()
    assert f"<h2>{SECTIONS[protocol]}</h2>" in html
    assert check_report(out) > 0  # every table of the report equals what the results give
    learned = read_sections(out / "report.html").get("Did the agents learn?")
    printed = capsys.readouterr().out
    if learned is not None:  # the terminal says what the report's table says
        verdicts = {r["learned"] for r in learned["tables"]["Training contexts"]}
        assert ("yes: every kind of agent clearly beats" in printed) == (verdicts == {"yes"})
        assert ("warning:" in printed) == (verdicts != {"yes"})
    if protocol == "hpo":
        best = yaml.safe_load((out / "best.yaml").read_text())
        schedule = pd.read_parquet(out / "curves" / "chunk-0000.parquet")
        assert sorted(schedule["trial"]) == ["member-0", "member-1"]
        tuned = next(iter(schedule.filter(like="hp.").columns)).removeprefix("hp.")
        assert best[tuned] in schedule[f"hp.{tuned}"].tolist()
    elif agent != "random":
        assert "<h2>Did the agents learn?</h2>" in html
        checkpoints = {p.stem for p in (out / "checkpoints").glob("*.npz")}
        assert checkpoints == set(table["trial"])


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["hpo", "--agent", "random"],
            "hpo tunes a trained agent; random does not learn",
        ),
        (
            ["tabular", "--agent", "sac"],
            "agent: the tabular protocol trains no agent on an environment, so agent='sac'",
        ),
        (["tabular", "--env", "Pendulum"], "env: the tabular protocol trains no agent"),
        (
            ["visibility", "--env", "LunarLanderContinuous", "--agent", "dqn"],
            "the dqn agent acts in discrete action spaces; LunarLanderContinuous has Box",
        ),
        (
            ["sensitivity", "--env", "LunarLander", "--agent", "sac"],
            "the sac agent acts in continuous action spaces; LunarLander has Discrete(4)",
        ),
        (
            ["visibility", "--agent", "random", "--address", "auto"],
            "--address auto: only --executor ray and the hpo protocol use a Ray cluster",
        ),
    ],
)
def test_meaningless_combinations_are_refused_in_one_line(argv, message, tmp_path, capsys):
    assert contextrl(["run", *argv, "--root", str(tmp_path)]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and message in error, error
    assert not list(tmp_path.iterdir())  # nothing was made
