"""The workflow's figures and tables: return against a feature from hand-made results, natural sort,
figure titles that do not overlap."""

import itertools

import numpy as np
import pandas as pd
import pytest

from contextrl.analysis import plots
from contextrl.analysis.intervals import Interval
from contextrl.analysis.scores import natural_key, return_lines, score_cells
from contextrl.experiments.reports import per_context_table


def results_frame() -> pd.DataFrame:
    """Two variants × two seeds × three contexts of one varied feature; return = 10·length + seed."""
    rows = []
    for variant, seed, (index, length) in itertools.product(
        ["hidden", "concat"], [0, 1], enumerate([0.2, 0.4, 0.8])
    ):
        rows.append(
            {
                "trial": f"t-{variant}-s{seed}",
                "kind": "visibility",
                "variant": variant,
                "seed": seed,
                "train_set": "train",
                "test_set": "test",
                "context_index": index,
                "ctx.length": length,
                "ctx.gravity": 9.8,
                "return": 10 * length + seed + (variant == "concat"),
            }
        )
    return pd.DataFrame(rows)


def test_return_lines_and_per_context_table_by_hand():
    frame = results_frame()
    lines = return_lines(frame, "ctx.length")
    assert list(lines) == ["concat", "hidden"]
    x, runs = lines["hidden"]
    np.testing.assert_allclose(x, [0.2, 0.4, 0.8])
    np.testing.assert_allclose(runs, [[2, 4, 8], [3, 5, 9]])  # seeds × points
    table = per_context_table(score_cells(frame))
    assert list(table.columns[:4]) == ["agent", "test_set", "context_index", "length"]
    assert "gravity" not in table  # not varied
    row = table[(table["agent"] == "hidden") & (table["context_index"] == 2)].iloc[0]
    assert row["mean_return"] == pytest.approx(8.5) and row["seeds"] == 2
    assert row["std_return"] == pytest.approx(np.std([8, 9], ddof=1))


def test_natural_sort():
    names = ["random-10", "random-2", "random-1", "paper", "random-0"]
    assert sorted(names, key=natural_key) == [
        "paper",
        "random-0",
        "random-1",
        "random-2",
        "random-10",
    ]


def overlapping_titles(figure) -> list[tuple[str, str]]:
    """Pairs of figure/panel titles whose drawn boxes intersect."""
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    texts = [figure._suptitle] if figure._suptitle is not None else []
    texts += [axis.title for axis in figure.axes if axis.get_title()]
    boxes = [(t.get_text(), t.get_window_extent(renderer)) for t in texts]
    return [
        (a, b)
        for (a, box_a), (b, box_b) in itertools.combinations(boxes, 2)
        if box_a.overlaps(box_b)
    ]


def test_figure_titles_do_not_overlap_panel_titles():
    interval = {"mean": Interval(1, 0, 2), "median": Interval(1, 0, 2), "IQM": Interval(1, 0, 2)}
    figure = plots.intervals({"a": interval, "b": interval}, title="Test return (95% CI)")
    assert overlapping_titles(figure) == []
    returns = {name: {0.5: [1, 2], 1.0: [2, 3], 2.0: [0, 1]} for name in ["l", "g", "m", "dt"]}
    figure = plots.sensitivity_ecdfs(
        returns, title="Pendulum: agent trained on the default context"
    )
    assert overlapping_titles(figure) == []
