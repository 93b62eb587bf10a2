"""One aggregation for every report number: each protocol's report built from a constructed results
table (the rows a run writes, no training) states the same statistic alike wherever it appears, and
equal to a hand computation; the learned-or-not check per agent kind; missing cells named, never
dropped; the sensitivity table per variant.

Hand computations in each test; IQM = the mean of the middle 50 % of all run × context returns, with
floor(n/4) values cut from each end.
"""

import re

import numpy as np
import pandas as pd
import pytest

from contextrl.analysis import metrics, plots
from contextrl.analysis.scores import score_cells, score_matrices
from contextrl.experiments import RunDir, expand, parse_spec, report
from contextrl.experiments.compare import compare_runs
from contextrl.experiments.runs import write_parquet
from tests.helpers.constructed_results import result_rows
from tests.helpers.report_tables import check_one_statement, point, read_sections, row

pytestmark = pytest.mark.quick

REPS = 50  # bootstrap replicates: the intervals' width is not under test, only their sameness


@pytest.fixture
def unrendered(monkeypatch):
    """Figures built but not drawn to PNG: drawing is most of a report's time, and figures have
    their own tests (the missing-cell test here draws its masked lines and bands)."""
    monkeypatch.setattr(plots, "to_png", lambda figure, dpi=100: b"")


def sections(run_or_html) -> dict[str, dict]:
    path = run_or_html if str(run_or_html).endswith(".html") else report(run_or_html)
    return read_sections(path)


def iqm(values) -> float:
    flat = np.sort(np.ravel(values))
    cut = flat.size // 4
    return float(np.mean(flat[cut : flat.size - cut]))


# What the intervals of agents tested on drawn contexts resample, as the reports say it.
DRAWN = "seeds (each with all its contexts) and the test contexts"


def per_context_cis(found: dict) -> list[dict]:
    """The interval table of the per-context section (every agent of the run)."""
    tables = found["Test return per context"]["tables"]
    (title,) = [t for t in tables if t.startswith("Test return (95% CI over seeds")]
    return tables[title]


def make_run(tmp_path, name: str, data: dict):
    """A run folder of a 2-seed CartPole PPO spec (``data`` adds to it and overrides; hpo trains a
    population instead of seeds, so its spec has none)."""
    base = {"env": "CartPole", "agent": "ppo", "bootstrap_reps": REPS}
    if data.get("protocol") != "hpo":
        base["seeds"] = 2
    spec = parse_spec({**base, **data})
    return spec, RunDir.create(spec, out=str(tmp_path / name))


# ---------------------------------------------------------------- optimality gap, compare, eval

GENERAL = np.array([[1.0, 3.0, 5.0], [2.0, 6.0, 4.0]])  # seeds × contexts
SPECIALISTS = np.array([[4.0, 5.0, 9.0], [2.0, 7.0, 8.0]])  # specialist i's return in column i
OPTGAP = {
    "protocol": "optimality_gap",
    "train": {"length": {"uniform": [0.3, 0.7]}},
    "num_contexts": 3,
    "variants": ["hidden", "concat_varying"],
    "batch_size": 1,  # one trial per chunk: a failed chunk is one missing specialist
}


def optgap_returns(shift: float = 0.0, variants=("hidden", "concat_varying")) -> dict:
    out = {}
    for v, variant in enumerate(variants):
        offset = shift + 1000.0 * v  # the second variant far from the first
        for seed in range(2):
            out[f"general-{variant}-s{seed}"] = GENERAL[seed] + offset
            for i in range(3):
                out[f"specialist{i}-{variant}-s{seed}"] = [SPECIALISTS[seed, i] + offset]
    return out


def optgap_run(tmp_path, name: str, shift: float = 0.0):
    spec, run = make_run(tmp_path, name, OPTGAP)
    write_parquet(run.result_path(0), result_rows(spec, optgap_returns(shift)))
    return spec, run


def test_one_seed_optimality_gap_says_no_interval_everywhere(tmp_path, monkeypatch):
    """Before: the table said "(no interval with one seed)" while the text printed the gap as
    ``-46.87 [-77.1, -11.3]`` and the figure titled "no interval" drew interval bars."""
    drawn = []

    def keep(figure, dpi=100) -> bytes:
        drawn.append(figure)
        return b""

    monkeypatch.setattr(plots, "to_png", keep)
    spec, run = make_run(tmp_path, "run", {**OPTGAP, "seeds": 1, "variants": ["hidden"]})
    returns = {"general-hidden-s0": GENERAL[0]}
    returns |= {f"specialist{i}-hidden-s0": [SPECIALISTS[0, i]] for i in range(3)}
    write_parquet(run.result_path(0), result_rows(spec, returns))
    gap = sections(run.path)["Optimality gap (hidden)"]
    assert row(gap["tables"]["Aggregates"], agent="general")["mean"] == (
        "3 (no interval with one seed)"
    )
    assert not any(re.search(r"\[-?\d", line) for line in gap["text"]), gap["text"]
    # specialists (4, 5, 9) − general (1, 3, 5): (3 + 2 + 4) / 3 = 3
    assert "= 3 (no interval with one seed)" in " ".join(gap["text"])
    assert check_one_statement("Optimality gap (hidden)", gap) == 1
    (figure,) = [f for f in drawn if f._suptitle and "Aggregate return" in f._suptitle.get_text()]
    assert figure._suptitle.get_text() == "Aggregate return (no interval with one seed)"
    for axis in figure.axes:
        assert not axis.patches  # no interval bar
        assert len(axis.collections) == 2  # a point mark per agent


@pytest.mark.usefixtures("unrendered")
def test_optimality_gap_report_states_one_specialist_iqm(tmp_path):
    """Before: the per-context section pivoted the specialists on context_index (0 for every one)
    and gave IQM 5.833 of the seeds' means; the optimality-gap section re-keyed them and gave 6."""
    _, run = optgap_run(tmp_path, "a")
    found = sections(run.path)
    gap = found["Optimality gap (hidden)"]
    aggregates = gap["tables"]["Aggregates"]
    per_context = per_context_cis(found)
    # sorted specialist returns 2 4 5 7 8 9: cut one each end → (4 + 5 + 7 + 8) / 4 = 6
    assert iqm(SPECIALISTS) == 6.0
    for agent, label, scores in [
        ("specialists", "specialist, hidden", SPECIALISTS),
        ("general", "general, hidden", GENERAL),
    ]:
        here, there = row(aggregates, agent=agent), row(per_context, agent=label)
        for statistic in ("mean", "median", "IQM"):
            assert here[statistic] == there[statistic]  # point and interval
        assert point(here["IQM"]) == pytest.approx(iqm(scores), abs=5e-4)
        means = scores.mean(axis=0)  # per-context means over seeds
        assert point(here["mean"]) == pytest.approx(means.mean(), abs=5e-4)
        assert point(here["median"]) == pytest.approx(np.median(means), abs=5e-4)
        assert here["cells (seeds × contexts)"] == "all 6 (2 seeds × 3 contexts)"
    # gap: specialist means (3, 6, 8.5) − general means (1.5, 4.5, 4.5) → (1.5 + 1.5 + 4) / 3
    assert any(re.search(r"\] = 2\.333 \[", line) for line in gap["text"])
    table = pd.read_csv(run.path / "results" / "per_context.csv")
    mine = table[table["agent"] == "specialist, hidden"].sort_values("context")
    np.testing.assert_allclose(mine["mean_return"], SPECIALISTS.mean(axis=0))
    assert list(mine["seeds"]) == [2, 2, 2]


@pytest.mark.usefixtures("unrendered")
def test_compare_and_eval_read_the_same_cells(tmp_path):
    """``contextrl report A B`` states run A's statistics as A's own report does; ``contextrl
    eval``'s section computes on the same cells (specialists on shared contexts: each seed's cell
    is the mean over the specialists)."""
    spec, a = optgap_run(tmp_path, "a")
    optgap_run(tmp_path, "b", shift=100.0)
    new = np.array([[0.5, 1.5], [2.5, 3.5]])  # general: seeds × the 2 new contexts
    rows = result_rows(spec, optgap_returns())
    frames = []
    for trial in expand(spec).trials:
        returns = new[trial.seed] + (trial.variant != "hidden") * 1000.0
        if trial.kind == "specialist":  # specialist i: + i, so the mean over i adds 1
            returns = returns + int(re.match(r"specialist(\d+)", trial.id)[1])
        frames.append(
            pd.DataFrame(
                {
                    **rows[rows["trial"] == trial.id]
                    .iloc[0][["trial", "kind", "variant", "seed", "train_set"]]
                    .to_dict(),
                    "test_set": "far",
                    "context_index": [0, 1],
                    "ctx.length": [1.0, 1.4],
                    "return": returns,
                    "episodes": 1,
                    "contexts": "length ~ uniform:1.0:1.5",
                }
            )
        )
    write_parquet(a.path / "evaluations" / "far.parquet", pd.concat(frames, ignore_index=True))
    own = sections(a.path)
    out = compare_runs([a.path, tmp_path / "b"], tmp_path / "compare.html")
    compared = sections(out)["Comparison"]["tables"][
        f"Test return (95% CI over {DRAWN}, each with its runs)"
    ]
    aggregates = own["Optimality gap (hidden)"]["tables"]["Aggregates"]
    for agent, label in [
        ("specialists", "a: specialist, hidden"),
        ("general", "a: general, hidden"),
    ]:
        for statistic in ("mean", "median", "IQM"):
            assert row(compared, agent=label)[statistic] == row(aggregates, agent=agent)[statistic]
    shifted = row(compared, agent="b: specialist, hidden")
    assert point(shifted["IQM"]) == pytest.approx(iqm(SPECIALISTS) + 100.0, abs=5e-4)
    evaluated = own["Evaluation on new contexts: far"]
    cis = evaluated["tables"][f"Test return (95% CI over {DRAWN})"]
    assert point(row(cis, agent="general, hidden")["IQM"]) == pytest.approx(iqm(new), abs=5e-4)
    # the specialists' cell of a seed: mean over i of new + i = new + 1
    assert point(row(cis, agent="specialist, hidden")["IQM"]) == pytest.approx(iqm(new + 1.0))
    assert any("mean over its 3 agents" in line for line in evaluated["text"])


# ---------------------------------------------------------------- learned-or-warn per kind


@pytest.mark.usefixtures("unrendered")
def test_learning_check_is_per_kind_and_names_the_kind_that_failed(tmp_path):
    """Before: grouped by variant only, a general agent at the random policy's 10 hid behind
    specialists at 100 (pooled mean 77.5 vs 10: "yes", no warning)."""
    spec, run = make_run(tmp_path, "run", OPTGAP)  # the check needs no results
    plan = expand(spec)
    training = pd.DataFrame(
        [
            {
                "trial": t.id,
                "kind": t.kind,
                "variant": t.variant,
                "seed": t.seed,
                "train_return": 10.0 if t.kind == "general" else 100.0,
                "random_return": 10.0,
            }
            for t in plan.trials
            if t.variant == "hidden"
        ]
    )
    write_parquet(run.path / "training" / "chunk-0000.parquet", training)
    learning = sections(run.path)["Did the agents learn?"]
    rows = learning["tables"]["Training contexts"]
    assert row(rows, kind="general")["learned"] == "NO"
    assert row(rows, kind="specialist")["learned"] == "yes"
    (warning,) = learning["warnings"]
    assert "kind general (hidden)" in warning and "mean return 10 vs random 10" in warning

    # one specialist that learned nothing among others that did: named by its training set
    failed = training["trial"].str.startswith("specialist1-")
    training.loc[failed | (training["kind"] == "general"), "train_return"] = 100.0
    training.loc[failed, "train_return"] = 10.5
    write_parquet(run.path / "training" / "chunk-0000.parquet", training)
    learning = sections(run.path)["Did the agents learn?"]
    rows = learning["tables"]["Training contexts"]
    assert row(rows, kind="specialist")["learned"] == "NO for 1 of 3 training sets"
    (warning,) = learning["warnings"]
    assert "specialist trained on train[1]: mean return 10.5 vs random 10" in warning


# ---------------------------------------------------------------- refuse or say, never drop


def test_missing_cell_is_named_and_statistics_use_what_exists(tmp_path):
    """Before: a failed specialist chunk dropped seed 1 of every specialist (IQM 6 from seed 0's
    three returns) and the report said nothing of the missing cell."""
    spec, run = make_run(tmp_path, "run", {**OPTGAP, "variants": ["hidden"]})
    returns = optgap_returns(variants=("hidden",))
    del returns["specialist1-hidden-s1"]
    write_parquet(run.result_path(0), result_rows(spec, returns))
    plan = expand(spec)
    chunk = next(
        c
        for c, members in enumerate(plan.chunks)
        if plan.trials[members[0]].id == "specialist1-hidden-s1"
    )
    run.record_failure(chunk, ["specialist1-hidden-s1"], "RuntimeError('boom')", "Traceback …")
    found = sections(run.path)
    (missing,) = found["Missing results"]["tables"]["Missing results"]
    assert missing["agent"] == "specialist, hidden" and missing["seed"] == "1"
    assert missing["test set"] == "train[1]" and missing["contexts"] == "1"
    assert missing["why"] == f"specialist1-hidden-s1: chunk {chunk} failed: RuntimeError('boom')"
    gap = found["Optimality gap (hidden)"]
    specialists = row(gap["tables"]["Aggregates"], agent="specialists")
    present = [4.0, 5.0, 9.0, 2.0, 8.0]  # every cell but (seed 1, context 1)
    # sorted 2 4 5 8 9: cut one each end → (4 + 5 + 8) / 3
    assert point(specialists["IQM"]) == pytest.approx(iqm(present), abs=5e-4)
    # per-context means over the seeds that exist: 3, 5, 8.5
    assert point(specialists["mean"]) == pytest.approx((3.0 + 5.0 + 8.5) / 3, abs=5e-4)
    assert specialists["cells (seeds × contexts)"].startswith("5 of 6 (2 seeds × 3 contexts")
    per_context = per_context_cis(found)
    assert row(per_context, agent="specialist, hidden")["IQM"] == specialists["IQM"]
    # gap on the contexts both have: (3 − 1.5) + (5 − 4.5) + (8.5 − 4.5), over 3
    assert any(re.search(r"\] = 2 \[", line) for line in gap["text"])
    assert any("Computed on the cells that exist" in line for line in gap["text"])


def test_non_finite_return_is_a_named_missing_cell():
    rows = pd.DataFrame(
        {
            "trial": ["t-s0", "t-s0", "t-s1", "t-s1"],
            "kind": "visibility",
            "variant": "hidden",
            "seed": [0, 0, 1, 1],
            "test_set": "test",
            "context_index": [0, 1, 0, 1],
            "return": [1.0, 2.0, np.nan, 4.0],
        }
    )
    (scores,) = score_matrices(score_cells(rows)).values()
    assert scores.missing == ((1, "test", 0, "its return is nan"),)
    # context 0 has seed 0 only (1), context 1 both seeds (2, 4): (1 + 3) / 2
    assert scores.present == 3 and metrics.aggregate_mean(scores.matrix) == pytest.approx(2.0)
    with pytest.raises(ValueError, match="NaN"):  # a NaN is never taken for a missing cell
        metrics.aggregate_mean(rows["return"].to_numpy())


# ---------------------------------------------------------------- the other protocols


@pytest.mark.usefixtures("unrendered")
def test_sensitivity_table_has_every_variant_and_names_what_ran(tmp_path):
    """Before: one row per feature from the first variant, the default return averaged over both
    variants (150.5), and the text said "(hidden)" whatever ran."""
    spec, run = make_run(
        tmp_path,
        "run",
        {
            "protocol": "sensitivity",
            "features": ["length"],
            "magnitudes": [0.5, 1.0, 2.0],
            "variants": ["concat_all", "gated"],
        },
    )
    # contexts: the default (A = 1), length × 0.5, length × 2; + seed
    base = {"concat_all": [100.0, 50.0, 20.0], "gated": [200.0, 220.0, 120.0]}
    returns = {
        f"default-{variant}-s{seed}": np.add(values, seed)
        for variant, values in base.items()
        for seed in range(2)
    }
    write_parquet(run.result_path(0), result_rows(spec, returns))
    found = sections(run.path)["Sensitivity"]
    rows = found["tables"]["Return per feature"]
    for variant, (default, half, double) in base.items():
        mine = row(rows, feature="length", variant=variant)
        means = {1.0: default + 0.5, 0.5: half + 0.5, 2.0: double + 0.5}  # mean over seeds 0, 1
        worst = min(means, key=means.get)
        assert float(mine["return at A=1 (default context)"]) == means[1.0]
        assert float(mine["worst A"]) == worst and float(mine["return at worst A"]) == means[worst]
        assert float(mine["mean over A"]) == pytest.approx(np.mean(list(means.values())), abs=0.01)
    text = " ".join(found["text"])
    assert "concat_all, gated" in text and "hidden" not in text
    table = pd.read_csv(run.path / "results" / "per_context.csv")
    default = table[(table["context_index"] == 0) & (table["agent"] == "gated")]
    assert float(default["mean_return"].iloc[0]) == 200.5  # the table's A = 1 for gated


def test_one_seed_sensitivity_ecdf_draws_every_magnitude(tmp_path, monkeypatch):
    """Before: with one seed every panel was empty (a one-value eCDF drew no line), the default
    context (A = 1) was left out and the colour bar ran 0-0.5, one colour for every curve."""
    drawn = []

    def keep(figure, dpi=100) -> bytes:
        drawn.append(figure)
        return b""

    monkeypatch.setattr(plots, "to_png", keep)
    spec, run = make_run(
        tmp_path,
        "run",
        {
            "protocol": "sensitivity",
            "seeds": 1,
            "features": ["length", "gravity"],
            "magnitudes": [0.5, 1.0],
            "variants": ["hidden"],
        },
    )
    # contexts: the default (A = 1), length × 0.5, gravity × 0.5
    write_parquet(run.result_path(0), result_rows(spec, {"default-hidden-s0": [100, 40, 70]}))
    report(run.path)
    (ecdf,) = [f for f in drawn if any(a.get_title() == "gravity" for a in f.axes)]
    panels = [axis for axis in ecdf.axes if axis.get_title() in ("length", "gravity")]
    assert len(panels) == 2
    for axis in panels:
        lines = axis.get_lines()
        assert [line.get_label() for line in lines] == ["A=0.5", "A=1"]
        for line in lines:
            assert np.ptp(line.get_ydata()) == 1.0  # a one-value eCDF: one step from 0 to 1
        assert lines[0].get_color() != lines[1].get_color()
    assert [line.get_xdata()[0] for line in panels[0].get_lines()] == [40, 100]
    (colour_bar,) = [axis for axis in ecdf.axes if axis not in panels and axis.get_ylabel()]
    assert colour_bar.get_ylim() == (0.5, 1.0)


@pytest.mark.usefixtures("unrendered")
def test_visibility_report_states_one_value_per_statistic(tmp_path):
    spec, run = make_run(
        tmp_path,
        "run",
        {
            "protocol": "visibility",
            "train": {"length": {"uniform": [0.3, 0.7]}},
            "num_train_contexts": 2,
            "num_test_contexts": 3,
            "variants": ["hidden", "concat_all"],
        },
    )
    hidden = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    returns = {
        f"visibility-{variant}-s{seed}": hidden[seed] + 10.0 * (variant != "hidden")
        for variant in ("hidden", "concat_all")
        for seed in range(2)
    }
    write_parquet(run.result_path(0), result_rows(spec, returns))
    found = sections(run.path)
    here = row(found["Context visibility"]["tables"]["Test return"], agent="hidden")
    # the intervals are shown once: the per-context section does not repeat the table (it did)
    assert [
        c for c in found["Test return per context"]["tables"] if c.startswith("Test return")
    ] == []
    assert point(here["mean"]) == pytest.approx(hidden.mean(), abs=5e-4)
    assert point(here["IQM"]) == iqm(hidden) == 3.5  # 2 3 4 5 of 1…6
    # concat_all's worst return (11) is above hidden's best (6): P = 1
    assert any(
        line.startswith("P(concat_all > hidden) = 1 [")
        for line in found["Context visibility"]["text"]
    )


@pytest.mark.usefixtures("unrendered")
def test_train_test_region_means_match_the_per_context_means(tmp_path):
    spec, run = make_run(
        tmp_path,
        "run",
        {
            "protocol": "train_test",
            "modes": ["A"],
            "variants": ["hidden"],
            "test_box": {"length": [0.05, 0.95], "tau": [0.005, 0.035]},
            "num_train_contexts": 2,
            "num_test_contexts": 9,  # a 3 × 3 grid: centre inside, edges one out, corners both
        },
    )
    squares = np.arange(9.0) ** 2
    returns = {f"modeA-hidden-s{seed}": squares + 10.0 * seed for seed in range(2)}
    write_parquet(run.result_path(0), result_rows(spec, returns))
    found = sections(run.path)
    regions = found["Train/test modes"]["tables"][
        "Mean return per region (95% CI over seeds, each with all its contexts)"
    ]
    table = pd.read_csv(run.path / "results" / "per_context.csv")
    for region, contexts in [
        ("interpolation", [4]),
        ("extrapolation (one)", [1, 3, 5, 7]),
        ("extrapolation (both)", [0, 2, 6, 8]),
    ]:
        hand = np.mean(squares[contexts]) + 5.0  # seeds add 0 and 10
        mine = row(regions, region=region)
        assert point(mine["mean return"]) == pytest.approx(hand, abs=5e-3)
        listed = table[table["region"] == region]
        assert listed["mean_return"].mean() == pytest.approx(hand)
    overall = row(per_context_cis(found), agent="hidden")
    assert point(overall["mean"]) == pytest.approx(squares.mean() + 5.0, abs=5e-3)


@pytest.mark.usefixtures("unrendered")
def test_hpo_report_states_the_best_members_mean_once(tmp_path):
    spec, run = make_run(
        tmp_path,
        "run",
        {
            "protocol": "hpo",
            "variants": ["hidden"],
            "train": {"length": {"uniform": [0.3, 0.7]}},
            "num_test_contexts": 3,
        },
    )
    plan = expand(spec)
    test = plan.sets["test"]
    rows = pd.DataFrame(
        {
            "trial": "best",
            "kind": "best",
            "variant": "hidden",
            "seed": 0,
            "test_set": "test",
            "context_index": np.arange(3),
            **{f"ctx.{n}": np.asarray(getattr(test.contexts, n)) for n in spec.space().names},
            **{f"hp.{name}": low for name, (low, _) in spec.bounds().items()},
            "return": [10.0, 20.0, 60.0],
        }
    )
    write_parquet(run.result_path(0), rows)
    found = sections(run.path)
    (text,) = [
        line
        for line in found["Hyper-parameter optimisation (PB2)"]["text"]
        if line.startswith("Best member")
    ]
    assert "mean return 30, worst context 10, best 60." in text
    # the best member is one agent, one seed: its mean is said without an interval
    tables = found["Test return per context"]["tables"]
    overall = row(tables["Test return (no interval with one seed)"], agent="hidden")
    assert overall["mean"] == "30 (no interval with one seed)"


@pytest.mark.usefixtures("unrendered")
def test_tabular_gaps_match_hand_computation(tmp_path):
    """The tabular protocol has no seeds or agents (exact solutions), so no score matrix: its gaps
    are the optimality-gap metric on 1 × contexts matrices."""
    spec = parse_spec({"protocol": "tabular"})
    run = RunDir.create(spec, out=str(tmp_path / "run"))
    optimal, oblivious, stochastic = [10.0, 10.0, 10.0], [10.0, 1.0, 1.0], [10.0, 4.0, 1.0]
    frame = pd.DataFrame(
        {
            "trial": "paper",
            "test_set": "tabular",
            "context_index": [0, 1, 2],
            "optimal_return": optimal,
            "oblivious_return": oblivious,
            "stochastic_return": stochastic,
            "return": stochastic,
            "oblivious_policy": "(0, 0, 0)",
            "stochastic_policy": "[1.0, 1.0, 1.0]",
            "conflict_states": "(0,)",
        }
    )
    write_parquet(run.result_path(0), frame)
    (solution,) = sections(run.path)["Tabular cMDPs"]["tables"]["Solutions"]
    assert float(solution["deterministic gap (exact)"]) == 6.0  # (0 + 9 + 9) / 3
    assert float(solution["stochastic gap (upper bound)"]) == 5.0  # (0 + 6 + 9) / 3
