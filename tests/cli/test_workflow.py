"""The researcher's workflow through the ``contextrl`` command, run as a subprocess as a user runs it:
one-line errors (a traceback only with --debug), Ctrl-C with a resume hint, dry runs, saved agents
evaluated on new contexts, runs overlaid, TensorBoard logs, files that respect the umask."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from tests.helpers import ROOT

EXAMPLES = ROOT / "examples"


def contextrl(*argv, cwd, umask=None, timeout=300):
    """Run ``contextrl ARGV`` in a fresh interpreter; returns the CompletedProcess."""
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    return subprocess.run(
        [sys.executable, "-m", "contextrl.cli", *map(str, argv)],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        preexec_fn=None if umask is None else (lambda: os.umask(umask)),
    )


def one_line_error(result, *fragments):
    """The command failed with status 2 and one stderr line holding every fragment, no traceback."""
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


TINY_RANDOM = ["--agent", "random", "--max-steps", "10", "--episodes", "1", "--seeds", "1"]


@pytest.mark.parametrize(
    ("argv", "files", "fragments"),
    [
        (
            ["run", "--config", "bad.yaml"],
            {"bad.yaml": "protocol: visibility\nenv: [CartPole\n"},
            ["--config bad.yaml: YAML syntax error at line 3", "expected ','"],
        ),
        (
            ["run", "--config", "options.yaml"],
            {"options.yaml": 'protocol: visibility\nagent_options: "total_timesteps=1000"\n'},
            ["agent_options: expected a mapping", "agent_options: {total_timesteps: 1000}"],
        ),
        (
            ["run", "--config", "weights.yaml", "--dry-run"],
            {
                "weights.yaml": "protocol: visibility\ntrain:\n  length:\n    categorical: "
                "{choices: [0.3, 0.6], weights: [1, 2, 3]}\n"
            },
            ["length: categorical has 2 choices but 3 weights"],
        ),
        (
            ["run", "visibility", *TINY_RANDOM, "--out", "a_file/run"],
            {"a_file": ""},
            ["--out a_file/run: cannot create the run directory", "Not a directory"],
        ),
        (
            ["run", "visibility", *TINY_RANDOM, "--out", "/proc/contextrl-run"],
            {},
            ["--out /proc/contextrl-run: cannot create the run directory", "writable"],
        ),
        (
            ["run", "sensitivity", "--agent", "random", "--set", "magnitudes=[0.5,100]"],
            {},
            ["magnitudes: [100] put every feature outside its bounds"],
        ),
        (
            ["run", "sensitivity", "--agent", "random", "--vary", "length"]
            + ["--set", "magnitudes=[0.5,100]"],
            {},
            ["A=100 gives length = 50, outside its bounds [0.05, 5]", "choose A in [0.1, 10]"],
        ),
        (
            ["run", "train_test", "--agent", "random", "--set", "num_test_contexts=150"],
            {},
            ["num_test_contexts: the test contexts form a side × side grid", "use 144 or 169"],
        ),
        (
            ["run", "--resume", "somewhere", "--seeds", "5"],
            {"somewhere/spec.yaml": "protocol: visibility\n"},
            ["--resume somewhere continues the run as its spec.yaml says; --seeds cannot apply"],
        ),
        (
            ["render", "CartPole", "--out", "pole.mp4"],
            {},
            ["--out pole.mp4: unknown suffix '.mp4'", ".gif", ".png"],
        ),
        (
            ["render", "CartPole", "--grid", "length=0.3,1", "--grid", "length=2"],
            {},
            ["names a feature twice"],
        ),
    ],
)
def test_user_errors_are_one_line(argv, files, fragments, tmp_path):
    for name, text in files.items():
        write(tmp_path / name, text)
    before = set(tmp_path.iterdir())
    one_line_error(contextrl(*argv, cwd=tmp_path), *fragments)
    assert set(tmp_path.iterdir()) == before  # nothing half made


def test_debug_shows_the_traceback(tmp_path):
    write(tmp_path / "bad.yaml", "protocol: [\n")
    result = contextrl("--debug", "run", "--config", "bad.yaml", cwd=tmp_path)
    assert result.returncode == 1 and "Traceback" in result.stderr
    assert "SpecError: --config bad.yaml: YAML syntax error" in result.stderr


@pytest.mark.parametrize(
    "argv",
    [
        ["visibility", *TINY_RANDOM, "--executor", "ray"],
        ["hpo", "--set", "population=2"],  # PB2 runs on Ray Tune whatever the executor
    ],
)
def test_ray_address_without_a_cluster_is_one_line_and_makes_nothing(argv, tmp_path):
    """Port 1 of this machine has no cluster, whatever else runs here (``auto`` would join any local
    Ray, such as one another test file started)."""
    result = contextrl("run", *argv, "--address", "127.0.0.1:1", cwd=tmp_path)
    one_line_error(result, "--address 127.0.0.1:1: no Ray cluster answers there", "ray start")
    assert not (tmp_path / "runs").exists()


def test_yaml_numbers_vary_merge_and_dry_run(tmp_path):
    """``1e5`` is a number; --vary replaces one feature of the config and says so; the dry run counts
    trials, chunks and steps (checked by hand) and writes nothing."""
    config = write(
        tmp_path / "spec.yaml",
        "protocol: visibility\nvariants: [hidden]\nseeds: 3\nagent_options: {total_timesteps: 1e5}\n"
        "num_test_contexts: 4\neval_episodes: 2\nmax_steps: 50\nbatch_size: 2\n"
        "train:\n  length: {uniform: [0.3, 0.6]}\n  gravity: {uniform: [5, 10]}\n",
    )
    result = contextrl(
        "run", "--config", config, "--vary", "length=uniform:0.2:0.4", "--dry-run", cwd=tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "train keeps ['gravity'] from the config and replaces ['length']" in result.stderr
    out = result.stdout
    assert "trials: 3 (visibility)" in out and "chunks: 2 (up to 2 trials" in out
    # 3 trials x 99,840 steps (195 whole rollouts of 4 copies x 128 steps); evaluation at most
    # 3 x (4 test + 2 x 16 own) contexts x 2 x 50 steps
    assert "environment steps: 299,520 training, at most 10,800 evaluation" in out
    assert "results: runs/" in out and "time: not estimated (--estimate times it)" in out
    assert set(tmp_path.iterdir()) == {config}


def test_dry_run_calibrates_a_time_estimate(tmp_path):
    result = contextrl(
        "run", "visibility", *TINY_RANDOM, "--variants", "hidden,concat_all", "--dry-run",
        "--estimate", "--set", "num_train_contexts=2", "--set", "num_test_contexts=2", cwd=tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "trials: 2" in result.stdout and "chunks: 2" in result.stdout
    assert "calibration: the first chunk (1 trials) compiled once" in result.stdout
    assert "estimated time:" in result.stdout
    assert not list(tmp_path.iterdir())


def test_dry_run_of_a_trained_agent_times_a_short_budget_and_writes_nothing(tmp_path):
    """The estimate comes from one call at a small budget (the progress lines give the training
    rate), not from training the first chunk; no run directory is made."""
    result = contextrl(
        "run", "visibility", "--agent", "ppo", "--timesteps", "40000", "--agent-option",
        "num_steps=16", "--variants", "hidden", "--seeds", "1", "--max-steps", "20", "--episodes",
        "1", "--set", "num_train_contexts=2", "--set", "num_test_contexts=2", "--dry-run",
        "--estimate", cwd=tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "run at 2,000 steps" in result.stdout, result.stdout
    assert "training at the measured steps/s" in result.stdout
    assert "estimated time:" in result.stdout and "steps/s  recent" not in result.stdout
    assert not list(tmp_path.iterdir())


def test_dry_run_estimates_from_an_earlier_run_of_the_same_spec(tmp_path):
    argv = ["run", "visibility", *TINY_RANDOM, "--set", "num_train_contexts=2"]
    argv += ["--set", "num_test_contexts=2"]
    assert contextrl(*argv, "--quiet", cwd=tmp_path).returncode == 0
    (earlier,) = (tmp_path / "runs").iterdir()
    result = contextrl(*argv, "--seed", "7", "--dry-run", "--estimate", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert (
        f"timings of 1 earlier run(s) of this spec in runs (newest: {earlier.relative_to(tmp_path)}"
        in result.stdout
    )
    assert "nothing was compiled or trained" in result.stdout
    assert [p.name for p in (tmp_path / "runs").iterdir()] == [earlier.name]


@pytest.mark.parametrize(
    ("options", "fragment"),
    [
        (["--executor", "threads"], "executor: unknown executor 'threads'"),
        (["--address", "localhost:1"], "--address localhost:1: only --executor ray"),
        (["--out", "a_file/run"], "--out a_file/run: cannot create the run directory"),
    ],
)
def test_dry_run_refuses_what_the_run_refuses(tmp_path, options, fragment):
    """A dry run checks the options as the run does, so it fails with the run's own message."""
    write(tmp_path / "a_file", "")
    argv = ["run", "visibility", *TINY_RANDOM, *options]
    dry = one_line_error(contextrl(*argv, "--dry-run", cwd=tmp_path), fragment)
    assert one_line_error(contextrl(*argv, cwd=tmp_path), fragment) == dry
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]


def test_ctrl_c_exits_at_once_with_a_resume_hint(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    argv = ["run", "visibility", "--timesteps", "204800", "--out", "run", "--max-steps", "500"]
    process = subprocess.Popen(
        [sys.executable, "-m", "contextrl.cli", *argv],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    line = process.stderr.readline()  # "run directory: run", printed just before compiling
    assert line.startswith("run directory: run"), line
    time.sleep(1.0)  # now compiling or training
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=120)  # a guard against a hang, not a speed claim
    assert process.returncode == 130
    assert "interrupted; resume with: contextrl run --resume run" in err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert (tmp_path / "run" / "spec.yaml").exists()
    # It stopped where it was: not one chunk of 204,800 training steps per agent was finished
    # (400 whole rollouts, so no note on a rounded budget comes before the run directory).
    assert not list((tmp_path / "run").glob("results/*.parquet"))


def test_tabular_config_runs_and_files_follow_the_umask(tmp_path):
    result = contextrl(
        "run", "--config", EXAMPLES / "tabular.yaml", "--set", "num_random=2", "--out", "tab",
        "--quiet", cwd=tmp_path, umask=0o027,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    files = [p for p in (tmp_path / "tab").rglob("*") if p.is_file()]
    assert files and {p.stat().st_mode & 0o777 for p in files} == {0o640}
    html = (tmp_path / "tab" / "report.html").read_text()
    # natural order (random-2 before random-10 would need 11 cMDPs; 0 and 1 suffice to check order)
    assert html.index("random-0") < html.index("random-1")
    spec_section = html.split("<h2>Spec</h2>")[1]
    assert "seeds:" not in spec_section and "variants:" not in spec_section


def test_render_defaults_formats_grids_and_case(tmp_path):
    assert (
        contextrl("render", "CartPole", "--out", "x.gif", "--steps", "2", cwd=tmp_path).returncode
        == 0
    )
    with Image.open(tmp_path / "x.gif") as gif:
        assert gif.format == "GIF" and gif.n_frames == 3
    result = contextrl(
        "render", "cartpole", "--out", "x.png", "--steps", "1",
        "--grid", "length=0.3,1", "--grid", "gravity=5,10,15", cwd=tmp_path,
    )  # fmt: skip
    assert result.returncode == 0 and "6 panel(s)" in result.stdout
    with Image.open(tmp_path / "x.png") as png:
        assert png.format == "PNG"
    described = contextrl("describe", "cartpole", cwd=tmp_path)
    assert described.returncode == 0 and described.stdout.startswith("CartPole (classic_control")


# ---- a trained run: saved agents, eval on new contexts, overlay, TensorBoard --------------------------
PPO_TINY = [
    "run", "visibility", "--variants", "concat_varying", "--seeds", "2",
    "--timesteps", "64", "--agent-option", "num_envs=2", "--agent-option", "num_steps=16",
    "--agent-option", "num_minibatches=1", "--max-steps", "30", "--episodes", "2",
    "--set", "num_train_contexts=3", "--set", "num_test_contexts=4", "--set", "bootstrap_reps=50",
    "--set", "batch_size=4", "--vary", "length=uniform:0.3:0.6", "--quiet",
]  # fmt: skip


@pytest.fixture(scope="module")  # trained once: make test runs a file's tests in one worker
def trained_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("trained")
    result = contextrl(*PPO_TINY, "--out", "run", "--log", "tensorboard", cwd=folder)
    assert result.returncode == 0, result.stderr
    return folder / "run"


def test_report_has_the_feature_figure_and_per_context_csv(trained_run):
    figures = {p.stem for p in (trained_run / "figures").glob("*.png")}
    assert {"return-vs-length", "training-curves"} <= figures
    assert "environment-radar" not in figures
    table = pd.read_csv(trained_run / "results" / "per_context.csv")
    results = pd.concat(
        pd.read_parquet(p) for p in (trained_run / "results").glob("chunk-*.parquet")
    )
    assert len(table) == 4  # one variant x test contexts
    row = table.iloc[2]
    same = results[results["context_index"] == row["context_index"]]
    assert row["mean_return"] == pytest.approx(same["return"].mean())
    assert row["length"] == pytest.approx(same["ctx.length"].iloc[0])
    html = (trained_run / "report.html").read_text()
    assert "from the classic_control family" in html and "Acrobot" not in html


def test_load_policy_rebuilds_a_saved_agent(trained_run):
    import jax

    from contextrl.agents import load_checkpoint, load_policy, ppo

    saved = load_policy(trained_run / "checkpoints" / "visibility-concat_varying-s0")  # no .npz
    assert isinstance(saved.config, ppo.PPOConfig) and saved.config.variant == "concat_varying"
    assert saved.env_id == "CartPole" and saved.agent == "ppo" and saved.env.max_steps == 30
    lengths = np.asarray(saved.train_contexts.length)
    assert len(lengths) == 3 and lengths.min() >= 0.3 and lengths.max() <= 0.6
    params = load_checkpoint(trained_run / "checkpoints" / "visibility-concat_varying-s0.npz")
    leaves = jax.tree_util.tree_leaves(params)
    assert all(
        np.array_equal(a, b)
        for a, b in zip(leaves, jax.tree_util.tree_leaves(saved.params), strict=True)
    )
    contexts = saved.env.context_space.stack([saved.env.context_space.make(length=0.5)])
    returns = saved.evaluate(contexts, 2, jax.random.key(0))
    assert returns.shape == (1,) and 1 <= float(returns[0]) <= 30


def test_eval_tests_saved_agents_on_new_contexts(trained_run):
    result = contextrl(
        "eval", trained_run, "--test", "length=uniform:1.0:2.0", "--contexts", "3",
        "--episodes", "1", "--name", "long", cwd=trained_run.parent,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "evaluated 2 agents on 3 contexts" in result.stdout
    frame = pd.read_parquet(trained_run / "evaluations" / "long.parquet")
    assert len(frame) == 2 * 3 and frame["ctx.length"].between(1.0, 2.0).all()
    assert not (trained_run / "checkpoints" / ".tmp").exists()
    assert (trained_run / "evaluations" / "long.csv").exists()
    html = (trained_run / "report.html").read_text()
    assert "Evaluation on new contexts: long" in html
    assert (trained_run / "figures" / "eval-long-return-vs-length.png").exists()
    one_line_error(
        contextrl("eval", trained_run, "--test", "length=uniform:1:9", cwd=trained_run.parent),
        "length",
        "bounds",
    )


def test_report_overlays_two_runs(trained_run, tmp_path):
    import shutil

    other = tmp_path / "other"
    shutil.copytree(trained_run, other)
    result = contextrl("report", trained_run, other, "--out", "both.html", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    html = (tmp_path / "both.html").read_text()
    assert "run: concat_varying" in html and "other: concat_varying" in html
    assert html.count('data-figure="compare-') == 3  # intervals, return vs length, training


def scalars(folder: Path) -> dict[str, list[tuple[int, float]]]:
    """Scalars of the TensorBoard event files in ``folder`` (TFRecord framing: length, CRC, event, CRC)."""
    import struct

    from tensorboardX.proto import event_pb2

    out: dict[str, list[tuple[int, float]]] = {}
    for file in sorted(folder.glob("events.out.tfevents.*")):
        data = file.read_bytes()
        offset = 0
        while offset < len(data):
            (length,) = struct.unpack("<Q", data[offset : offset + 8])
            event = event_pb2.Event.FromString(data[offset + 12 : offset + 12 + length])
            offset += 12 + length + 4
            for value in event.summary.value:
                out.setdefault(value.tag, []).append((event.step, value.simple_value))
    return out


def test_tensorboard_holds_curves_and_test_returns(trained_run):
    logged = scalars(trained_run / "tensorboard" / "visibility-concat_varying-s1")
    assert set(logged) == {"train/episode_return", "test/mean_return"}
    curve = pd.concat(pd.read_parquet(p) for p in (trained_run / "curves").glob("chunk-*.parquet"))
    curve = curve[curve["trial"] == "visibility-concat_varying-s1"]
    steps, values = zip(*logged["train/episode_return"], strict=True)
    assert list(steps) == curve["step"].tolist()
    assert np.allclose(values, curve["episode_return"])
    results = pd.concat(
        pd.read_parquet(p) for p in (trained_run / "results").glob("chunk-*.parquet")
    )
    mean = results.loc[results["trial"] == "visibility-concat_varying-s1", "return"].mean()
    assert logged["test/mean_return"] == [(0, pytest.approx(mean))]


def test_eval_on_a_host_environment_run(tmp_path):
    """A dm_control run's agents are evaluated in host copies of the new contexts."""
    pytest.importorskip("dm_control")
    result = contextrl(
        "run", "visibility", "--env", "DmcWalker", "--agent", "random", "--variants", "hidden",
        "--seeds", "1", "--max-steps", "5", "--episodes", "1", "--set", "num_train_contexts=2",
        "--set", "num_test_contexts=2", "--vary", "viscosity=uniform:0:1", "--out", "walker",
        "--quiet", cwd=tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    result = contextrl(
        "eval", "walker", "--test", "viscosity=uniform:2:4", "--contexts", "2", "--episodes", "1",
        cwd=tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    frame = pd.read_parquet(tmp_path / "walker" / "evaluations" / "eval-1.parquet")
    assert len(frame) == 2 and frame["ctx.viscosity"].between(2, 4).all()
    assert np.isfinite(frame["return"]).all()


def test_vary_merges_with_a_config_feature_by_feature():
    from contextrl.context.distributions import Uniform
    from contextrl.experiments import PROTOCOLS

    data = {"protocol": "visibility", "train": {"length": {"uniform": [0.3, 0.6]}, "tau": 0.03}}
    notice = PROTOCOLS["visibility"].vary_spec(data, ["length=uniform:0.2:0.4"])
    assert data["train"] == {"length": Uniform(0.2, 0.4), "tau": 0.03}
    assert (
        notice
        == "--vary: train keeps ['tau'] from the config and replaces ['length']; now ['length', 'tau']"
    )
    data = {"protocol": "sensitivity", "features": ["g"]}
    assert "keeps ['g']" in PROTOCOLS["sensitivity"].vary_spec(data, ["l"])
    assert data["features"] == ["g", "l"]
    data = {"protocol": "sensitivity"}  # the default, every feature: --vary narrows it
    assert PROTOCOLS["sensitivity"].vary_spec(data, ["l"]) is None and data["features"] == ["l"]
    data = {"protocol": "train_test", "train_box": {"length": [0.3, 0.6], "tau": [0.01, 0.02]}}
    PROTOCOLS["train_test"].vary_spec(data, ["tau=[0.015,0.025]"])
    assert data["train_box"] == {"length": [0.3, 0.6], "tau": [0.015, 0.025]}
