"""The sharp edges a new user hits on the command line: protocol
defaults that fit the environment, ``report`` refusing runs that do not share an axis, the learned-or-
warn verdict in the terminal, messages that say what was expected, ``--version`` / ``python -m
contextrl``, one-seed intervals said as such, and third-party noise kept out of the terminal.

Cheap by construction: dry runs (nothing compiled), runs of zero chunks, constructed result tables;
nothing here trains an agent.
"""

import importlib.util
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from contextrl.analysis import plots
from contextrl.analysis.intervals import SAMPLED
from contextrl.analysis.scores import Scores, score_intervals
from contextrl.cli import main
from contextrl.context.distributions import Constant, Uniform
from contextrl.experiments import RunDir, expand, parse_spec
from contextrl.experiments.runs import write_parquet
from contextrl.experiments.spec import ENV_DEFAULTS, parse_assignments, parse_distribution
from tests.helpers import ROOT
from tests.helpers.constructed_results import result_rows


@pytest.fixture(autouse=True)
def unrendered(monkeypatch):
    """Figures built but not drawn: drawing is a report's main cost, and has its own tests."""
    monkeypatch.setattr(plots, "to_png", lambda figure, dpi=100: b"")


def cli(capsys, *argv) -> tuple[int, str, str]:
    """``contextrl ARGV`` in this process: (status, stdout, stderr)."""
    status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


def one_line_error(status: int, err: str, *fragments: str) -> str:
    assert status == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err and "Errno" not in err, err
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


def python(*argv, cwd) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    return subprocess.run(
        [sys.executable, *argv], cwd=cwd, env=env, capture_output=True, text=True, timeout=300
    )


# ---- protocol defaults come from the environment ---------------------------------------------
DRY = ["--dry-run"]


@pytest.mark.parametrize("protocol", ["visibility", "optimality_gap", "train_test", "hpo"])
def test_protocol_defaults_fit_the_environment(protocol, capsys):
    """Before: every protocol's default training set was CartPole's ``length``, so on Pendulum
    "train: unknown context feature 'length' for PendulumContext"."""
    status, out, err = cli(capsys, "run", protocol, "--env", "Pendulum", "--agent", "sac", *DRY)
    assert status == 0, err
    spec = parse_spec({"protocol": protocol, "env": "Pendulum", "agent": "sac"})
    field = "train_box" if protocol == "train_test" else "train"
    assert "l" in getattr(spec, field) and "length" not in getattr(spec, field)


@pytest.mark.parametrize("env", sorted(ENV_DEFAULTS))
def test_every_declared_default_is_a_valid_spec(env):
    for protocol in ("visibility", "optimality_gap", "train_test"):
        parse_spec({"protocol": protocol, "env": env, "agent": "random"})


def test_an_environment_without_a_default_needs_vary(capsys):
    status, _, err = cli(capsys, "run", "visibility", "--env", "Platformer", *DRY)
    one_line_error(
        status, err, "needs --vary for Platformer", "e.g. --vary level_width=uniform:", "gravity"
    )


# ---- report refuses runs that do not share an axis (or overlays them labelled) ----------------
def constructed_run(tmp_path, name: str, env: str, train: dict, seeds: int = 2) -> RunDir:
    """A visibility run folder with a results table written as a run writes it (no training)."""
    spec = parse_spec(
        {
            "protocol": "visibility",
            "env": env,
            "agent": "ppo",
            "variants": ["hidden"],
            "seeds": seeds,
            "train": train,
            "num_train_contexts": 2,
            "num_test_contexts": 3,
            "bootstrap_reps": 20,
        }
    )
    run = RunDir.create(spec, out=str(tmp_path / name))
    returns = {t.id: np.arange(3.0) + t.seed for t in expand(spec).trials}
    write_parquet(run.result_path(0), result_rows(spec, returns))
    return run


CARTPOLE = {"length": {"uniform": [0.25, 0.75]}}


def test_report_refuses_runs_of_different_environments(tmp_path, capsys):
    """Before: a CartPole and a MountainCar run were overlaid without a word."""
    a = constructed_run(tmp_path, "a", "CartPole", CARTPOLE)
    b = constructed_run(tmp_path, "b", "MountainCar", {"gravity": {"uniform": [0.002, 0.003]}})
    out = tmp_path / "both.html"
    status, _, err = cli(capsys, "report", a.path, b.path, "--out", out)
    one_line_error(status, err, "differ in env", "a: CartPole", "b: MountainCar", "--force")
    assert not out.exists()
    status, _, err = cli(capsys, "report", a.path, b.path, "--out", out, "--force")
    assert status == 0, err
    html = out.read_text()
    assert "a [CartPole, length]: hidden" in html and "b [MountainCar, gravity]: hidden" in html


def test_report_refuses_runs_of_different_features(tmp_path, capsys):
    a = constructed_run(tmp_path, "a", "CartPole", CARTPOLE)
    b = constructed_run(tmp_path, "b", "CartPole", {"gravity": {"uniform": [5.0, 15.0]}})
    status, _, err = cli(capsys, "report", a.path, b.path, "--out", tmp_path / "x.html")
    one_line_error(status, err, "differ in features", "a: length", "b: gravity")


def test_runs_naming_one_environment_two_ways_overlay(tmp_path, capsys):
    """Before: a run of ``--env cartpole`` and one of CartPole were refused as differing in env;
    a spec now holds the registry's id whatever spelling or alias named it."""
    a = constructed_run(tmp_path, "a", "cartpole", CARTPOLE)
    b = constructed_run(tmp_path, "b", "CARLCartPole", CARTPOLE)
    assert a.spec().env == b.spec().env == "CartPole"
    status, _, err = cli(capsys, "report", a.path, b.path, "--out", tmp_path / "x.html")
    assert status == 0, err


def test_report_refuses_a_run_given_twice(tmp_path, capsys):
    """Before: "several agents share a (seed, test set, context) cell; label each kind and
    variant apart"."""
    run = constructed_run(tmp_path, "a", "CartPole", CARTPOLE)
    status, _, err = cli(capsys, "report", run.path, f"{run.path}/", "--out", tmp_path / "x.html")
    one_line_error(status, err, "given twice; give each run once")


def test_report_of_one_run_goes_where_out_says(tmp_path, capsys):
    """Before: ``report RUN --out x.html`` was refused ("--out is for several runs")."""
    run = constructed_run(tmp_path, "a", "CartPole", CARTPOLE)
    out = tmp_path / "shared" / "x.html"
    status, printed, err = cli(capsys, "report", run.path, "--out", out)
    assert status == 0, err
    assert f"report: {out}" in printed
    assert out.read_text() == (run.path / "report.html").read_text()
    assert "Context visibility" in out.read_text()
    status, _, err = cli(capsys, "report", run.path, "--out", tmp_path / "x.pdf")
    one_line_error(status, err, f"--out {tmp_path / 'x.pdf'}", "name it *.html")


def test_resume_counts_the_runs_chunks_and_previews_what_is_left(tmp_path, capfd):
    """Before: ``--resume DIR --max-chunks 1`` printed ``[1/1 chunks]`` for the second of two
    chunks, and ``--resume DIR --dry-run`` was refused."""
    out = tmp_path / "run"
    quick = ["--agent", "random", "--seeds", "1", "--episodes", "1", "--max-steps", "20"]
    assert main(["run", "quickstart", *quick, "--max-chunks", "1", "--out", str(out)]) == 0
    assert "[1/2 chunks] chunk 0" in capfd.readouterr().err
    assert main(["run", "--resume", str(out), "--dry-run"]) == 0
    preview = capfd.readouterr().out
    assert preview.startswith("dry run of resuming visibility (quickstart); nothing is written")
    assert "  finished: 1 of 2 chunks; left: 1 chunk(s), 0 training steps" in preview
    assert "chunk-0001" not in " ".join(p.name for p in (out / "results").iterdir())
    assert main(["run", "--resume", str(out), "--max-chunks", "1"]) == 0
    assert "[2/2 chunks] chunk 1" in capfd.readouterr().err


# ---- hpo's budget is rounds × steps_per_round --------------------------------------------------
def test_hpo_refuses_timesteps_it_would_ignore(capsys, tmp_path):
    """Before: --timesteps was ignored (each member trained rounds × steps_per_round) and then written
    into best.yaml as if it had been the budget."""
    argv = ["run", "hpo", "--timesteps", "5000", "--root", str(tmp_path), *DRY]
    status, _, err = cli(capsys, *argv)
    one_line_error(
        status, err, "hpo trains each member for rounds × steps_per_round", "--set steps_per_round="
    )
    assert not list(tmp_path.iterdir())  # nothing was made


# ---- the terminal ends with the report's learned-or-warn verdict -----------------------------
@pytest.mark.parametrize(("trained", "expected"), [(0.0, "warning: "), (500.0, "learn? yes")])
def test_run_ends_with_the_learning_verdict(trained, expected, tmp_path, capsys):
    """Before: only report.html warned that the agents did not learn; the terminal said nothing."""
    folder = tmp_path / "run"
    spec = parse_spec({"protocol": "visibility", "seeds": 1, "variants": ["hidden"]})
    run = RunDir.create(spec, out=str(folder))  # a run whose one chunk finished (no training)
    plan = expand(spec)
    trial = plan.trials[0]
    returns = {trial.id: np.zeros(len(plan.sets[trial.test_set]))}
    write_parquet(run.result_path(0), result_rows(spec, returns))
    training = pd.DataFrame(
        {
            "trial": [t.id for t in plan.trials],
            "kind": [t.kind for t in plan.trials],
            "variant": [t.variant for t in plan.trials],
            "seed": [t.seed for t in plan.trials],
            "train_return": trained,
            "random_return": 0.0,
        }
    )
    write_parquet(folder / "training" / "chunk-0000.parquet", training)
    status, out, err = cli(capsys, "run", "--resume", folder, "--quiet")
    assert status == 0, err
    assert expected in out.strip().splitlines()[-1]
    status, out, err = cli(capsys, "report", folder)
    assert status == 0 and expected in out.strip().splitlines()[-1], err
    if trained == 0.0:
        assert "do not clearly beat a random policy" in out


# ---- messages say what was expected, with an example -----------------------------------------
def test_a_number_on_the_command_line_is_a_number(capsys):
    """Before: ``--vary length=0.5`` → "expected a number, got str ('0.5')"."""
    assert parse_distribution("length", "0.5") == Constant(0.5)
    status, out, err = cli(capsys, "run", "visibility", "--vary", "length=0.5", *DRY)
    assert status == 0 and "train" in out, err


@pytest.mark.parametrize(
    ("option", "item", "form"),
    [
        ("--test", "length", "FEATURE=DIST"),
        ("--vary", "length=", "FEATURE=DIST"),
        ("--set", "=3", "NAME=VALUE"),
        ("--agent-option", "num_steps", "NAME=VALUE"),
    ],
)
def test_every_name_value_option_refuses_an_item_without_name_or_value(option, item, form, capsys):
    """Before: ``--test length`` (no ``=``) reached the distribution reader as the feature "length"
    with the value "", and ``--set seeds=`` set seeds to None; one reader now checks every such
    option alike. A distribution written as YAML reads in ``--vary`` as in a spec file."""
    status, _, err = cli(capsys, "run", "visibility", option, item, *DRY)
    one_line_error(status, err, f"{option}: expected {form}, got {item!r}")
    read = parse_assignments(
        ["length={uniform: [0.3, 0.6]}"], "--vary", "FEATURE=DIST", parse_distribution
    )
    assert read == {"length": Uniform(0.3, 0.6)}


def test_sensitivity_vary_takes_feature_names(capsys):
    """Before: "unknown context feature 'length=uniform:0.2:0.7'"."""
    status, _, err = cli(capsys, "run", "sensitivity", "--vary", "length=uniform:0.2:0.7", *DRY)
    one_line_error(status, err, "takes feature names", "e.g. --vary length", "magnitudes")


def test_a_distribution_with_missing_arguments_names_them(tmp_path, capsys):
    """Before: "Uniform.__init__() missing 1 required positional argument"."""
    config = tmp_path / "spec.yaml"
    config.write_text("protocol: visibility\ntrain: {length: {uniform: [0.25]}}\n")
    status, _, err = cli(capsys, "run", "--config", config, *DRY)
    one_line_error(status, err, "uniform takes [low, high]", "got [0.25]", "e.g. length: {uniform")
    assert "__init__" not in err


def test_out_at_an_existing_file_says_it_wants_a_folder(tmp_path, capsys):
    """Before: "[Errno 17] File exists"."""
    taken = tmp_path / "taken"
    taken.write_text("")
    status, _, err = cli(capsys, "run", "visibility", "--out", taken, *DRY)
    one_line_error(status, err, f"--out {taken}", "expected a folder", "e.g. --out")


def test_render_refuses_a_missing_folder(tmp_path, capsys):
    """Before: ``render --out /typo/dir/x.gif`` silently created /typo/dir."""
    target = tmp_path / "typo" / "dir" / "x.gif"
    status, _, err = cli(capsys, "render", "CartPole", "--out", target, "--steps", "1")
    one_line_error(status, err, "expected an existing folder", "e.g. --out x.gif")
    assert not (tmp_path / "typo").exists()


def test_render_refuses_more_frames_than_memory_holds(tmp_path, capsys, monkeypatch):
    """Before: ``--steps 100000000`` drew frames until the process was killed for memory."""
    from contextrl import cli as cli_module

    frame = 600 * 400 * 3  # CartPole's frame, in bytes
    monkeypatch.setattr(
        cli_module, "available_memory", lambda: cli_module.FRAME_COPIES * frame * 11
    )
    target = tmp_path / "x.gif"
    status, _, err = cli(capsys, "render", "CartPole", "--steps", "100000000", "--out", target)
    one_line_error(status, err, "--steps 100000000", "600×400", "at most --steps 10 fit")
    assert not target.exists()
    status, out, _ = cli(capsys, "render", "CartPole", "--steps", "10", "--out", target)
    assert status == 0 and "11 frames" in out


def test_render_refuses_a_feature_given_twice(tmp_path, capsys):
    """Before: ``--context length=0.5 --context length=1.5`` drew length 1.5 without a word."""
    argv = ["--context", "length=0.5", "--context", "length=1.5", "--out", tmp_path / "x.gif"]
    status, _, err = cli(capsys, "render", "CartPole", *argv)
    one_line_error(status, err, "--context: length is given twice; give it once")
    argv = ["--context", "length=0.5", "--grid", "length=1,1.5", "--out", tmp_path / "x.gif"]
    status, _, err = cli(capsys, "render", "CartPole", *argv)  # before: the grid's values won
    one_line_error(status, err, "--context and --grid both set length")


def test_render_refuses_a_frame_rate_a_gif_cannot_play(tmp_path, capsys):
    """Before: ``--fps 200`` wrote 20 ms frames, played at 50 frames per second."""
    status, _, err = cli(capsys, "render", "CartPole", "--fps", "200", "--out", tmp_path / "x.gif")
    one_line_error(status, err, "--fps 200: a GIF plays at most 50 frames per second")


def test_a_png_is_one_frame_and_says_so(tmp_path, capsys):
    """Before: a still of a two-panel grid reported "101 frames" (and drew them all)."""
    target = tmp_path / "grid.png"
    status, out, _ = cli(capsys, "render", "CartPole", "--grid", "length=0.5,1", "--out", target)
    assert status == 0 and "a still of the first frame, 2 panel(s)" in out, out
    from PIL import Image

    with Image.open(target) as still:
        assert still.width > 2 * 600  # both panels, side by side


def test_output_to_a_reader_that_went_away_ends_quietly(tmp_path):
    """Before: ``contextrl describe CartPole | head -1`` ended with "error: Broken pipe"."""
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    command = [sys.executable, "-m", "contextrl", "describe", "CartPole"]
    process = subprocess.Popen(
        command, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    process.stdout.close()  # the reader is gone before anything is written
    _, err = process.communicate(timeout=120)
    assert process.returncode == 141 and err == b"", err


# ---- --version, python -m contextrl, one-seed intervals, third-party noise ---------------------
def test_version_and_python_dash_m(tmp_path):
    import contextrl

    result = python("-m", "contextrl", "--version", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == f"contextrl {contextrl.__version__}"


def test_one_seed_has_no_interval(tmp_path, capsys):
    """Before: one seed gave a zero-width "95% CI" (a bootstrap over one seed)."""
    from contextrl.analysis.scores import interval_title

    one = {"a": Scores(np.ma.masked_invalid([[1.0, 2.0, 3.0]]), (), ())}
    _, rows = score_intervals(one, contexts=SAMPLED, reps=20, seed=0)
    assert rows[0]["mean"] == "2 (no interval with one seed)"
    assert interval_title("Test return", one, SAMPLED) == "Test return (no interval with one seed)"
    a = constructed_run(tmp_path, "a", "CartPole", CARTPOLE, seeds=1)
    b = constructed_run(tmp_path, "b", "CartPole", CARTPOLE, seeds=1)
    status, _, err = cli(capsys, "report", a.path, b.path, "--out", tmp_path / "x.html")
    assert status == 0, err
    html = (tmp_path / "x.html").read_text()
    assert "Test return (no interval with one seed)" in html and "95% CI" not in html


@pytest.mark.skipif(importlib.util.find_spec("brax") is None, reason="the brax extra")
def test_brax_loads_without_third_party_noise_or_a_mujoco_log(tmp_path):
    """Before: "Failed to import warp" (stdout), brax's UserWarning and MuJoCo's settotalmass
    deprecation warning (HalfCheetah's model), and MUJOCO_LOG.TXT in the current folder."""
    result = python("-c", "import contextrl as crl; crl.make('BraxHalfCheetah')", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout == "" and result.stderr == "", (result.stdout, result.stderr)
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


@pytest.mark.skipif(importlib.util.find_spec("dm_control") is None, reason="the dmc extra")
def test_dm_control_on_mjx_loads_without_mjxs_import_notices(tmp_path):
    """Before: every MJX command printed "Failed to import warp" and "Failed to import
    mujoco_warp" (MJX's first import, on stdout)."""
    result = python(
        "-c", "import contextrl as crl; crl.make('DmcWalker', backend='mjx')", cwd=tmp_path
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout == "" and result.stderr == "", (result.stdout, result.stderr)
