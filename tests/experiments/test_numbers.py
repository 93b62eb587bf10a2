"""The numbers in reports, checked by hand: optimality gap, IQM, probability of improvement, the
near-best fraction and the heat-map scale on a constructed results table, also with negative returns,
and the trained-versus-random check."""

import re

import numpy as np
import pandas as pd
import pytest

from contextrl.analysis import metrics, plots
from contextrl.analysis.scores import score_cells, score_matrices
from contextrl.experiments import RunDir, expand, parse_spec, report
from contextrl.experiments.reports import learning_section
from contextrl.experiments.runs import write_parquet

pytestmark = pytest.mark.quick

# 2 seeds × 2 contexts. Hand computation (see each test):
GENERAL = np.array([[1.0, 3.0], [2.0, 6.0]])
SPECIALISTS = np.array([[4.0, 5.0], [2.0, 7.0]])


def results_table(shift: float) -> pd.DataFrame:
    """The rows an optimality-gap run writes for GENERAL and SPECIALISTS (plus ``shift``)."""
    rows = []
    for seed in range(2):
        for context in range(2):
            rows.append(
                {
                    "trial": f"general-hidden-s{seed}",
                    "kind": "general",
                    "variant": "hidden",
                    "seed": seed,
                    "test_set": "train",
                    "context_index": context,
                    "context": context,
                    "return": GENERAL[seed, context] + shift,
                }
            )
            rows.append(
                {
                    "trial": f"specialist{context}-hidden-s{seed}",
                    "kind": "specialist",
                    "variant": "hidden",
                    "seed": seed,
                    "test_set": f"train[{context}]",
                    "context_index": 0,
                    "context": context,
                    "return": SPECIALISTS[seed, context] + shift,
                }
            )
    return pd.DataFrame(rows)


@pytest.mark.parametrize("shift", [0.0, -100.0])
def test_gap_iqm_and_improvement_match_hand_computation(shift):
    cells = score_cells(results_table(shift))
    scores = score_matrices(cells, cells["kind"])
    general, specialists = scores["general"].matrix, scores["specialist"].matrix
    np.testing.assert_array_equal(general, GENERAL + shift)
    np.testing.assert_array_equal(specialists, SPECIALISTS + shift)  # a column per context
    # per context, specialist mean − general mean: (3 − 1.5) and (6 − 4.5)
    assert metrics.context_optimality_gap(general, specialists) == pytest.approx(1.5)
    # sorted general returns 1, 2, 3, 6: the middle two average 2.5
    assert metrics.aggregate_iqm(general) == pytest.approx(2.5 + shift)
    # context 0: {4, 2} vs {1, 2}: 3 wins and a tie of 4 pairs = 0.875; context 1: {5, 7} vs {3, 6}: 0.75
    assert metrics.probability_of_improvement(specialists, general) == pytest.approx(0.8125)
    # best 7, worst 1 (+ shift): threshold 7 − 0.01 × 6; only one specialist score reaches it
    threshold = metrics.near_best_threshold(general, specialists)
    assert threshold == pytest.approx(6.94 + shift)
    assert metrics.fraction_solved(specialists, threshold) == 0.25
    assert metrics.fraction_solved(general, threshold) == 0.0


@pytest.mark.parametrize("shift", [0.0, -100.0])
def test_optimality_gap_report_states_the_hand_computed_values(shift, tmp_path):
    spec = parse_spec(
        {
            "protocol": "optimality_gap",
            "env": "Pendulum",
            "agent": "random",
            "train": {"l": {"uniform": [0.5, 1.5]}},
            "num_contexts": 2,
            "seeds": 2,
            "bootstrap_reps": 50,
        }
    )
    run = RunDir.create(spec, out=str(tmp_path / "run"))
    write_parquet(run.result_path(0), results_table(shift))
    html = open(report(run.path), encoding="utf-8").read()
    assert re.search(r"Optimality gap E_c\[.*\] = 1\.5 \[", html)
    assert "beats the general agent on a context: 0.8125 [" in html
    assert "general 0.00, specialists 0.25" in html
    assert f"<td>{2.5 + shift:.4g} [" in html  # the general agent's IQM


def test_heat_map_colour_scale_spans_negative_returns():
    x, y = np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 4))
    values = -800.0 + 100.0 * x.ravel()  # every return negative
    figure = plots.heatmap(x.ravel(), y.ravel(), values, xlabel="a", ylabel="b", bins=4)
    assert figure.axes[0].collections[0].get_clim() == (-800.0, -700.0)
    shared = plots.heatmap(
        x.ravel(), y.ravel(), values, xlabel="a", ylabel="b", bins=4, vmin=-900, vmax=-600
    )
    assert shared.axes[0].collections[0].get_clim() == (-900.0, -600.0)
    with pytest.raises(ValueError, match="vmin"):
        plots.heatmap(x.ravel(), y.ravel(), values, xlabel="a", ylabel="b", vmin=0.0, vmax=-700)


def test_report_warns_when_agents_do_not_beat_a_random_policy():
    spec = parse_spec(
        {
            "protocol": "visibility",
            "env": "Pendulum",
            "agent": "sac",
            "train": {"l": "uniform:0.5:1.5"},
        }
    )
    training = pd.DataFrame(
        {
            "trial": [
                f"visibility-{v}-s{seed}" for v in ("hidden", "concat_all") for seed in (0, 1)
            ],
            "kind": "visibility",
            "variant": ["hidden"] * 2 + ["concat_all"] * 2,
            "train_return": [-160.0, -140.0, -1150.0, -1100.0],
            "random_return": [-1200.0] * 4,
        }
    )
    section = learning_section(spec, training, expand(spec))
    rows = section.tables[0][1]
    # hidden: −150 is far above −1200; concat_all: −1125 is 75 above, less than 10% of 1200
    assert [row["learned"] for row in rows] == ["yes", "NO"]
    assert rows[1]["trained: mean return"] == pytest.approx(-1125.0)
    assert len(section.warnings) == 1 and "concat_all" in section.warnings[0]
