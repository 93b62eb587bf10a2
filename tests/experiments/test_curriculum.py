"""The curriculum protocol end to end: a tiny run from the CLI, its verdict table equal to the
difference of per-seed mean test returns read from the results, and its spec's refusals."""

import re

import numpy as np
import pandas as pd
import pytest

from contextrl.cli import main
from contextrl.experiments.spec import SpecError, parse_spec


def test_a_tiny_curriculum_run_reports_differences_computed_from_its_results(tmp_path):
    out = tmp_path / "run"
    main(
        [
            "run",
            "curriculum",
            "--seeds",
            "2",
            "--set",
            "curricula=[uniform, adr]",
            "--set",
            "agent_options={total_timesteps: 2048, num_envs: 8, num_steps: 64}",
            "--set",
            "num_train_contexts=8",
            "--set",
            "test_points=3",
            "--set",
            "eval_episodes=2",
            "--out",
            str(out),
        ]
    )
    results = pd.concat(pd.read_parquet(f) for f in (out / "results").glob("chunk-*.parquet"))
    assert sorted(results["kind"].unique()) == ["adr", "uniform"]
    lengths = np.sort(results["ctx.length"].unique())
    np.testing.assert_allclose(lengths, [0.05, 2.525, 5.0], rtol=1e-6)  # the grid's ends
    per_seed = results.groupby(["kind", "seed"])["return"].mean()
    expected = per_seed["adr"].mean() - per_seed["uniform"].mean()
    report = (out / "report.html").read_text()
    row = re.search(r"<td>adr</td><td>concat_varying</td><td>([-0-9.e]+) \[", report)
    assert row and float(row.group(1)) == pytest.approx(expected, rel=1e-3, abs=1e-3)
    curves = pd.concat(pd.read_parquet(f) for f in (out / "curves").glob("chunk-*.parquet"))
    adr = curves[curves["kind"] == "adr"]
    assert (adr["curriculum.low.0"] <= 0.5 + 1e-6).all() and (
        adr["curriculum.high.0"] >= 0.5 - 1e-6
    ).all()


@pytest.mark.quick
@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"curricula": ["uniform", "sgd"]}, "curricula: unknown 'sgd'"),
        ({"variants": ["hidden"]}, "SPaCE orders contexts"),
        ({"agent": "dqn"}, "PLR scores contexts by the positive advantage"),
        ({"agent": "random", "curricula": ["uniform", "adr"]}, "curricula run in the compiled"),
        ({"ranges": {"length": [0.05, 9.0]}}, "outside the feature's bounds"),
        ({"curriculum_options": {"plr": {"temperature": 0}}}, "temperature must be"),
        ({"adr_thresholds": [400]}, "adr_thresholds: give"),
    ],
)
def test_bad_curriculum_specs_are_refused_by_name(changes, message):
    with pytest.raises(SpecError, match=message):
        parse_spec({"protocol": "curriculum", "env": "CartPole", **changes})
