"""Edges a new user hits, each refused or handled in one line that names what was wrong and what is
valid: command-line flags that conflict or count nothing, options meant for another agent, a figure
or a folder not given, writing only where told, and the faces' own calls (gymnasium's ``make`` and
``reset`` options, CARL's ``env.context``, gymnax's ``registered_envs``).

Cheap by construction: dry runs without calibration, argument parsing, environments built once.
"""

import importlib.util

import gymnasium
import numpy as np
import pytest

import contextrl.gymnasium  # noqa: F401  (registers the gymnasium ids)
from contextrl.carl.envs import CARLCartPole
from contextrl.cli import main
from contextrl.context import ContextError, Uniform
from contextrl.paper import runs as paper_runs
from tests.helpers import ROOT

pytestmark = pytest.mark.quick

DRY = ["--dry-run"]


def cli(capsys, *argv) -> tuple[int, str, str]:
    """``contextrl ARGV`` in this process: (status, stdout, stderr); argparse's refusals included."""
    try:
        status = main([str(a) for a in argv])
    except SystemExit as exit_:
        status = exit_.code
    out, err = capsys.readouterr()
    return status, out, err


def refused(capsys, fragments, *argv) -> str:
    """The last stderr line of a refused command, checked to contain every fragment."""
    status, _, err = cli(capsys, *argv)
    assert status == 2, err
    assert "Traceback" not in err, err
    line = err.strip().splitlines()[-1]
    for fragment in fragments:
        assert fragment in line, line
    return line


@pytest.mark.parametrize(
    ("argv", "fragments"),
    [
        (["list", "--family", "dmcc"], ["--family: unknown family 'dmcc'; choose one of", "'dmc'"]),
        (
            ["run", "visibility", "--agent", "random", "--timesteps", "2000", *DRY],
            ["--timesteps 2000: the random agent does not train; leave --timesteps out"],
        ),
        (
            ["run", "visibility", "--max-chunks", "0", *DRY],
            ["expected a whole number of at least 1"],
        ),
        (["run", "visibility", "--max-chunks", "-1", *DRY], ["at least 1, got '-1'"]),
        (
            ["run", "visibility", "--agent-option", "hidden_sizes=64", *DRY],
            ["hidden_sizes must be a non-empty list of positive integers", "got 64"],
        ),
        (["paper", "run"], ["paper run: name a figure", "'tabular_cmdp'"]),
        (["paper", "list", "ecdf_pendulum"], ["paper list: takes no figure"]),
        (["docs"], ["the following arguments are required: --out"]),
        (["run", "visibility", "--quiet", "--verbose", *DRY], ["--quiet and --verbose: give one"]),
        (["run", "visibility", "--estimate"], ["--estimate goes with --dry-run"]),
        (
            ["run", "visibility", "--out", "somewhere", "--root", "elsewhere", *DRY],
            ["--out somewhere names the run directory, so --root elsewhere would be ignored"],
        ),
        (
            ["run", "visibility", "--resume", "nosuchdir"],
            ["--resume nosuchdir: no such folder (a run directory holds spec.yaml)"],
        ),
        (
            ["run", "visibility", "--vary", "length=uniform:nan:1.5", *DRY],
            ["length: Uniform: low must be finite, got nan"],
        ),
        (  # a plan is expanded in memory: a count beyond any run is refused before it is
            ["run", "visibility", "--seeds", "1e12", *DRY],
            ["seeds: expected an integer <= 1,000,000, got 1,000,000,000,000"],
        ),
        (["run", "visibility", "--set", "name=a/b", *DRY], ["names the run's folder"]),
        (["run", "visibility", "--set", "env=3", *DRY], ["env: expected a name (a string)"]),
        (["run", "visibility", "--variants", "", *DRY], ["variants: unknown variant ''"]),
        (  # before: the last one won without a word
            ["run", "visibility", "--vary", "length=uniform:0.2:0.4", "--vary", "length=0.3", *DRY],
            ["--vary: length is given twice (uniform:0.2:0.4, 0.3); give it once"],
        ),
        (  # before: --set won over --seeds without a word
            ["run", "visibility", "--set", "seeds=3", "--seeds", "4", *DRY],
            ["--set seeds=3 and --seeds 4 both set seeds; give one"],
        ),
        (
            ["run", "visibility", "--set", "eval_episodes=3", "--episodes", "4", *DRY],
            ["--set eval_episodes=3 and --episodes 4 both set eval_episodes; give one"],
        ),
        (  # before: "backend: CartPole: unknown argument 'backend'"
            ["run", "quickstart", "--set", "backend=mjx", *DRY],
            ["backend 'mjx': only the Brax and dm_control environments have a backend; CartPole"],
        ),
        (  # before: planned 10,000,000,000,000 training steps without a word
            ["run", "quickstart", "--timesteps", "1e12", *DRY],
            ["total_timesteps must be at most 2,147,483,647", "got 1,000,000,000,000"],
        ),
        (  # before: it named the warm-up but not the budget that works
            [
                "run",
                "visibility",
                "--env",
                "Pendulum",
                "--agent",
                "sac",
                "--timesteps",
                "1000",
                *DRY,
            ],
            ["leaves no full logging period", "the smallest budget that trains is 6000"],
        ),
    ],
)
def test_each_edge_is_refused_in_one_line_naming_it(argv, fragments, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing a refused command could write lands in the repository
    refused(capsys, fragments, *argv)
    assert not any(tmp_path.iterdir())


def test_an_agent_chosen_on_the_command_line_drops_options_written_for_another(capsys, tmp_path):
    """quickstart's spec carries PPO's options; with ``--agent random`` they are dropped, said once,
    instead of "the random agent takes no options" for options the user never wrote."""
    status, _, err = cli(capsys, "run", "quickstart", "--agent", "random", "--root", tmp_path, *DRY)
    assert status == 0, err
    assert "agent_options were written for ppo, so --agent random trains without them" in err


def test_quickstart_on_another_environment_leaves_cartpoles_contexts_out(capsys, tmp_path):
    """Before: ``run quickstart --env Pendulum`` failed on "unknown context feature 'length'"."""
    status, out, err = cli(
        capsys, "run", "quickstart", "--env", "Pendulum", "--root", tmp_path, *DRY
    )
    assert status == 0, err
    assert err.splitlines()[0] == (
        "note: quickstart's contexts vary CartPole's length, so on Pendulum they are left out: "
        "--vary and --test set them, else Pendulum's defaults for the visibility protocol apply"
    )
    assert "Pendulum, agent ppo" in out
    status, _, err = cli(
        capsys, "run", "quickstart", "--env", "CARLCartPole", "--root", tmp_path, *DRY
    )
    assert status == 0 and "left out" not in err  # an alias of CartPole keeps them


def test_a_budget_rounded_to_whole_rollouts_is_said_and_planned_as_trained(capsys, tmp_path):
    """Before: ``quickstart --timesteps 30000`` trained 29,696 steps an agent (29 rollouts of
    8 × 128) and planned 300,000 without a word."""
    status, out, err = cli(
        capsys, "run", "quickstart", "--timesteps", "30000", "--root", tmp_path, *DRY
    )
    assert status == 0, err
    assert err.strip() == (
        "note: ppo trains 29,696 of the 30,000 total_timesteps per agent "
        "(whole rollouts of num_envs × num_steps)"
    )
    assert "environment steps: 296,960 training" in out  # 10 agents
    status, _, err = cli(capsys, "run", "visibility", "--root", tmp_path, *DRY)
    assert status == 0 and "note" not in err  # a budget the command line did not give: no note


def test_sac_at_the_smallest_budget_it_names_is_accepted(capsys, tmp_path):
    argv = ["run", "visibility", "--env", "Pendulum", "--agent", "sac", "--root", tmp_path]
    status, _, err = cli(capsys, *argv, "--timesteps", "6000", *DRY)
    assert status == 0, err


def test_docs_write_only_where_told(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    status, out, _ = cli(capsys, "docs", "--out", "-")
    assert status == 0 and out.startswith("# Environments and context features")
    assert not any(tmp_path.iterdir())


def test_paper_reads_the_kept_runs_or_says_where_it_looked(capsys, tmp_path, monkeypatch):
    """Without kept runs (an installed wheel) the page is refused, saying where it looked; the
    listing still lists every figure, its estimates not measured."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(paper_runs, "REPOSITORY_RUNS", tmp_path / "none")
    refused(capsys, ["no runs in ./results/paper or", "give --runs FOLDER"], "paper", "page")
    status, out, _ = cli(capsys, "paper", "list")
    assert status == 0 and "kirk_cartpole" in out and "time (small): not measured" in out, out
    assert not any(tmp_path.iterdir())
    monkeypatch.setattr(paper_runs, "REPOSITORY_RUNS", ROOT / "results/paper")
    assert (
        paper_runs.kept_runs() == paper_runs.REPOSITORY_RUNS
    )  # a checkout's runs, from any folder


@pytest.mark.skipif(importlib.util.find_spec("Box2D") is None, reason="the box2d extra")
def test_a_host_environments_time_limit_points_at_where_it_is_set():
    """Before: ``crl.make("LunarLander", max_steps=5)`` said only "unknown argument"."""
    import contextrl as crl

    with pytest.raises(ValueError, match=r"ContextualGymEnv\('LunarLander', max_steps=N\)"):
        crl.make("LunarLander", max_steps=5)


def test_gymnasium_make_with_context_points_at_contexts():
    with pytest.raises(ValueError, match="unknown argument 'context'; a context is given as con"):
        gymnasium.make("contextrl/CartPole-v0", context={"length": 1.0})


def test_a_context_id_on_a_resampled_distribution_says_there_are_no_ids():
    env = gymnasium.make("contextrl/CartPole-v0", contexts={"length": Uniform(0.3, 0.7)})
    with pytest.raises(ContextError, match="drawn from a distribution at every reset, so there"):
        env.reset(seed=0, options={"context_id": 7})


def test_carl_env_context_is_checked_when_set():
    env = CARLCartPole()
    env.reset(seed=0)
    with pytest.raises(ContextError, match="unknown context feature 'bogus'"):
        env.context = {"bogus": 1.0}
    with pytest.raises(ContextError, match=r"length: value -5 is outside its bounds"):
        env.context = {"length": -5.0}
    env.context = {"length": 0.7}  # accepted: filled with the defaults, as every context
    assert env.context["length"] == pytest.approx(0.7) and np.isfinite(env.context["gravity"])
