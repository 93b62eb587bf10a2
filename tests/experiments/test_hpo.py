"""`contextrl run hpo`: PB2 on a local Ray tunes PPO on sampled contexts, reproducibly from the seed;
the best configuration feeds another protocol through --agent-config."""

import argparse
import contextlib
import io
import json
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
import yaml

from contextrl.cli import main as cli_main
from contextrl.experiments import SpecError, parse_spec
from contextrl.experiments.commands import add_run, spec_from_args
from contextrl.experiments.plan import expand
from tests.helpers.report_tables import check_report

BOUNDS = {"learning_rate": (1e-5, 1e-2), "ent_coef": (0.0, 0.05), "clip_eps": (0.1, 0.4)}


pytestmark = pytest.mark.usefixtures("shut_down_ray")


def test_hpo_search_bounds_are_checked_before_anything_runs():
    with pytest.raises(SpecError, match="'lr' is not a ppo option"):
        parse_spec({"protocol": "hpo", "search": {"lr": [0.1, 0.2]}})
    with pytest.raises(SpecError, match="empty range"):
        parse_spec({"protocol": "hpo", "search": {"learning_rate": [0.1, 0.01]}})
    with pytest.raises(SpecError, match="gamma"):  # a bound that is no valid setting
        parse_spec({"protocol": "hpo", "search": {"gamma": [0.9, 1.5]}})
    with pytest.raises(SpecError, match="at least 2 members"):
        parse_spec({"protocol": "hpo", "population": 1})


def test_fields_hpo_does_not_use_are_refused_not_ignored():
    with pytest.raises(
        SpecError, match="batch_size: the hpo protocol trains each member on its own"
    ):
        parse_spec({"protocol": "hpo", "batch_size": 4})
    assert parse_spec({"protocol": "hpo", "bootstrap_reps": 500}).bootstrap_reps == 500
    with pytest.raises(SpecError, match=r"seeds: 3 PB2 searches take base seeds 4294967294 to"):
        parse_spec({"protocol": "hpo", "seeds": 3, "seed": 2**32 - 2})
    several = parse_spec({"protocol": "hpo", "seeds": 3, "population": 2, "rounds": 2})
    assert several.training_steps(expand(several).trials) == 3 * 2 * 2 * 20_000  # 3 PB2 runs


def test_each_round_trains_with_the_rate_pb2_set_unless_annealing_per_round_is_asked():
    """PPO anneals its learning rate to 0 over its training; a PB2 round is a whole training, so an
    annealed schedule would restart at every round. hpo trains each round at the rate PB2 set;
    anneal_per_round names the other choice; giving anneal_lr is refused, as is annealing for an
    agent that has none."""
    spec = parse_spec({"protocol": "hpo", "agent": "ppo"})
    assert spec._config({"learning_rate": 1e-3}).anneal_lr is False
    spec = parse_spec({"protocol": "hpo", "agent": "ppo", "anneal_per_round": True})
    assert spec._config({"learning_rate": 1e-3}).anneal_lr is True
    with pytest.raises(SpecError, match="agent_options.anneal_lr: hpo trains each round with"):
        parse_spec({"protocol": "hpo", "agent": "ppo", "agent_options": {"anneal_lr": True}})
    with pytest.raises(SpecError, match="anneal_per_round: the dqn agent has no learning-rate"):
        parse_spec({"protocol": "hpo", "agent": "dqn", "anneal_per_round": True})


SHARED_ROUND = """
import dataclasses, json
import jax, numpy as np
from contextrl.experiments import expand, parse_spec
from contextrl.experiments.protocols.hpo import _round_trainer

options = {"num_envs": 4, "num_steps": 32, "hidden_sizes": [8]}
spec = parse_spec({"protocol": "hpo", "agent": "ppo", "steps_per_round": 256, "agent_options": options})
env, train_set = spec.make_env(), expand(spec).sets["train"].contexts
key = jax.random.key(0)

def leaves(params):
    return [np.asarray(leaf) for leaf in jax.tree_util.tree_leaves(params)]

def train(**hyper):
    return leaves(_round_trainer(spec, env, spec._config(hyper), train_set)(key, None))

def constant(**hyper):
    make_train = spec.agent_entry().make_train(spec._config(hyper), env, train_set)
    return leaves(jax.jit(lambda k: make_train(k).params)(key))

def close(a, b):  # two programs: equal up to float32 rounding, not always bit for bit
    return all(np.allclose(x, y, rtol=1e-5, atol=1e-6) for x, y in zip(a, b, strict=True))

first = train(learning_rate=1e-3, ent_coef=0.0, clip_eps=0.2)
events = []
listen = lambda name, **_: events.append(name)
jax.monitoring.register_event_listener(listen)
second = train(learning_rate=3e-3, ent_coef=0.01, clip_eps=0.3)
jax.monitoring.unregister_event_listener(listen)
untraceable = {"learning_rate": 3e-3, "log_std_init": -0.5}
spec = dataclasses.replace(spec, search={name: [-1.0, 1.0] for name in untraceable})
print(json.dumps({
    "hits": events.count("/jax/compilation_cache/cache_hits"),
    "misses": events.count("/jax/compilation_cache/cache_misses"),
    "as_constants": close(second, constant(learning_rate=3e-3, ent_coef=0.01, clip_eps=0.3)),
    "values_act": not close(first, second),
    "untraceable_as_constants": close(train(**untraceable), constant(**untraceable)),
}))
"""


def test_members_with_other_values_share_one_compiled_round(tmp_path):
    """The searched values are inputs of the compiled round, not constants: a member with other
    values runs the program another member compiled (read from the persistent cache, nothing
    compiled; each member used to compile its own) and trains as with constants (to float32 rounding:
    folding a constant may round differently, by one ulp under the suite's XLA flags). A searched
    value the agent cannot trace (PPO checks log_std_init's type in Python) stays a constant. Runs in
    a fresh process with an empty cache, so what the cache held before cannot decide the outcome."""
    environment = {**os.environ, "JAX_COMPILATION_CACHE_DIR": str(tmp_path / "cache")}
    done = subprocess.run(
        [sys.executable, "-c", SHARED_ROUND],
        env=environment,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    observed = json.loads(done.stdout.strip().splitlines()[-1])
    assert observed["hits"] >= 1 and observed["misses"] == 0, observed
    assert observed["as_constants"] and observed["values_act"], observed
    assert observed["untraceable_as_constants"], observed


@pytest.fixture(
    scope="module"
)  # the suite's costliest setup: made once (make test: --dist loadfile)
def pb2_runs(tmp_path_factory):
    """The same tiny PB2 run twice with --seed 7: two members, three rounds of 256 steps; the second
    with --seeds 2 (a second search from base seed 8). Ray's workers inherit the suite's JAX
    compilation cache (conftest.py), so the second run loads the programs the first compiled. The
    first run shows its progress; what it printed (from Python) is kept in terminal.txt beside it."""
    pytest.importorskip("ray")
    runs = []
    for name in ("first", "second"):
        out = tmp_path_factory.mktemp("hpo") / name
        argv = ["run", "hpo", "--env", "CartPole", "--agent", "ppo", "--seed", "7"]
        argv += ["--vary", "length=uniform:0.3:0.7", "--out", str(out)]
        argv += [] if name == "first" else ["--quiet", "--seeds", "2"]
        argv += ["--agent-option", "num_steps=32", "--agent-option", "hidden_sizes=[8]"]
        argv += ["--set", "population=2", "--set", "rounds=3", "--set", "steps_per_round=256"]
        argv += ["--set", "num_train_contexts=4", "--set", "num_test_contexts=5"]
        argv += ["--max-steps", "50", "--episodes", "2"]
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(printed):
            assert cli_main(argv) == 0
        (out.parent / "terminal.txt").write_text(printed.getvalue())
        runs.append(out)
    return runs


@pytest.mark.slow  # PB2 on a local Ray: pb2_runs
def test_terminal_shows_a_line_per_round_and_ray_writes_to_the_run_log(pb2_runs):
    """Tune's status tables and Ray's log lines, from starting the local Ray instance on, go to
    ray/ray.log in the run, not the terminal."""
    printed = (pb2_runs[0].parent / "terminal.txt").read_text()
    for member in (0, 1):
        for round_ in (1, 2, 3):
            assert f"hpo: member {member}, round {round_}/3: return " in printed
    for noise in ("Trial status", "Configuration for experiment", "View detailed results", "INFO"):
        assert noise not in printed, noise
    logged = (pb2_runs[0] / "ray" / "ray.log").read_text()
    assert "Started a local Ray instance" in logged and "Exploit" in logged
    assert "Configuration for experiment" in logged


def schedule(out) -> pd.DataFrame:
    return pd.read_parquet(out / "curves" / "chunk-0000.parquet")


@pytest.mark.slow  # PB2 on a local Ray: pb2_runs
def test_pb2_tunes_ppo_and_the_best_config_feeds_another_protocol(pb2_runs, tmp_path):
    out = pb2_runs[0]
    frame = schedule(out)
    # two members, three rounds of 256 steps each, every hyper-parameter within its bounds
    assert frame.groupby("trial")["step"].apply(list).to_dict() == {
        "member-0": [256, 512, 768],
        "member-1": [256, 512, 768],
    }
    for name, (low, high) in BOUNDS.items():
        assert frame[f"hp.{name}"].between(low, high).all()
    best = yaml.safe_load((out / "best.yaml").read_text())
    assert best["num_steps"] == 32 and 1e-5 <= best["learning_rate"] <= 1e-2
    results = pd.read_parquet(out / "results" / "chunk-0000.parquet")
    assert len(results) == 5 and results["ctx.length"].between(0.3, 0.7).all()
    assert results["hp.learning_rate"].iloc[0] == best["learning_rate"]
    # the best configuration is one a member trained with in the last round
    last = frame[frame["step"] == 768]
    assert best["learning_rate"] in last["hp.learning_rate"].tolist()
    html = (out / "report.html").read_text()
    assert "Hyper-parameter optimisation (PB2)" in html and 'data-figure="hpo-schedules"' in html
    # The summary says what was trained: the population, not the spec's unused seed count.
    assert "a population of 2 members, 3 rounds of 256 steps each (base seed 7)" in html
    assert "3 seeds" not in html
    # the best configuration as the agent of another protocol: the spec `contextrl run` would run
    parser = argparse.ArgumentParser()
    add_run(parser.add_subparsers())
    args = parser.parse_args(["run", "visibility", "--agent-config", str(out / "best.yaml")])
    assert parse_spec(spec_from_args(args)).agent_options == best


@pytest.mark.slow  # PB2 on a local Ray: pb2_runs
def test_same_seed_gives_the_same_schedules_and_best_configuration(pb2_runs):
    """The first PB2 run does not depend on how many follow it; the second search is another one."""
    first, second = pb2_runs
    pd.testing.assert_frame_equal(schedule(first), schedule(second))
    assert (first / "best.yaml").read_text() == (second / "best.yaml").read_text()
    columns = ["context_index", "return"]
    pd.testing.assert_frame_equal(
        pd.read_parquet(first / "results" / "chunk-0000.parquet")[columns],
        pd.read_parquet(second / "results" / "chunk-0000.parquet")[columns],
    )
    other = pd.read_parquet(second / "curves" / "chunk-0001.parquet")
    assert sorted(set(other["trial"])) == ["member-0-s1", "member-1-s1"]
    assert set(other["seed"]) == {1}
    names = [f"hp.{name}" for name in BOUNDS]
    assert not np.allclose(other[names].to_numpy(), schedule(second)[names].to_numpy())
    results = pd.read_parquet(second / "results" / "chunk-0001.parquet")
    assert set(results["trial"]) == {"best-s1"} and set(results["seed"]) == {1}
    assert (second / "best-s1.yaml").exists()
    html = (second / "report.html").read_text()
    assert "2 PB2 runs (base seeds 7 to 8), each a population of 2 members" in html
    assert check_report(second) > 0  # a best-configuration row per run, equal to the results


@pytest.mark.slow  # PB2 on a local Ray: pb2_runs
def test_pb2_changes_hyperparameters_between_rounds(pb2_runs):
    """An exploit/explore step happened: a member's hyper-parameters differ between two rounds, and
    each change took the parameters of the better member (its return before the step is lower)."""
    frame = schedule(pb2_runs[0])
    names = [f"hp.{name}" for name in BOUNDS]
    changes = 0
    for step_before, step_after in ((256, 512), (512, 768)):
        before = frame[frame["step"] == step_before].set_index("trial")
        after = frame[frame["step"] == step_after].set_index("trial")
        for member in before.index:
            if np.allclose(before.loc[member, names], after.loc[member, names]):
                continue
            changes += 1
            others = before.drop(index=member)
            assert before.loc[member, "episode_return"] <= others["episode_return"].max()
    assert changes >= 1


REPLAY = {"batch_size": 8, "log_every": 32, "buffer_size": 256, "learning_starts": 32}
HOST_CONTINUATION = [
    (
        "ppo",
        "CartPole",
        {"learning_rate": 1e-30, "total_timesteps": 64, "num_steps": 32, "num_envs": 2},
    ),
    ("dqn", "CartPole", {**REPLAY, "learning_rate": 1e-30, "total_timesteps": 96}),
    ("sac", "Pendulum", {**REPLAY, "policy_lr": 1e-30, "q_lr": 1e-30, "total_timesteps": 96}),
]


@pytest.mark.parametrize(("agent", "env_name", "options"), HOST_CONTINUATION)
def test_host_training_continues_the_given_parameters(agent, env_name, options):
    """What PB2 needs on a host environment: a round starts from the member's parameters (with a
    vanishing step size they come back unchanged), not from fresh ones, and reproducibly."""
    import jax

    import contextrl as crl
    from contextrl.agents import get_agent

    entry = get_agent(agent)
    env = crl.make(env_name)
    contexts = env.default_context()
    config = entry.config(env_name, {"hidden_sizes": [8], **options})
    given = entry.init_params(config, env, contexts, jax.random.key(5))

    def train(params):
        key = jax.random.key(0)
        return entry.train_host(config, env_name, contexts, key, seed=1, init_params=params)

    continued, again, fresh = train(given), train(given), train(None)
    pairs = zip(*(jax.tree_util.tree_leaves(r) for r in (given, continued.params)), strict=True)
    for before, after in pairs:
        np.testing.assert_allclose(np.asarray(after), np.asarray(before), rtol=0, atol=1e-20)
    for a, b in zip(
        *(jax.tree_util.tree_leaves(r.params) for r in (continued, again)), strict=True
    ):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    leaves = (jax.tree_util.tree_leaves(r) for r in (fresh.params, given))
    assert not all(np.allclose(a, b) for a, b in zip(*leaves, strict=True))
