"""The paper's figures (``contextrl paper``): every spec parses at every scale and runs end to end at
the tiny budget; the claim checks decide from intervals; the results page is generated from runs."""

from __future__ import annotations

import dataclasses
import html
import os
import re
import shutil
import types
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from contextrl.analysis.intervals import Interval
from contextrl.cli import main
from contextrl.experiments.plan import trial_columns
from contextrl.experiments.runner import run_experiment
from contextrl.experiments.runs import RunDir, agent_settings, write_parquet
from contextrl.experiments.spec import parse_spec
from contextrl.paper import (
    FIGURES,
    PAPER_RUNS,
    SCALES,
    PaperFigure,
    checks,
    results_page,
    run_figure,
    spec_data,
)
from contextrl.paper.catalogue import CAUSES, SPEC_FOLDER
from contextrl.paper.checks import (
    BRITTLE,
    EQUIVALENCE,
    GATE,
    HARMLESS,
    MARGIN_RULE,
    MIN_SEEDS,
    Check,
    Verdict,
    _all,
    _decide,
    _zone,
    better_check,
    gap_check,
    similar_check,
)
from contextrl.paper.plans import planned, training_steps
from contextrl.paper.runs import (
    _add_catalogue_seeds,
    _agent_settings,
    cpu_model,
    machines,
    plan_text,
    seconds_per_step,
    wall_seconds,
)
from tests.helpers import ROOT
from tests.helpers.report_tables import check_report


def test_every_spec_file_belongs_to_one_figure_and_states_its_paper_section_and_claim():
    files = [path for figure in FIGURES.values() for path in figure.files().values()]
    assert sorted(files) == sorted(SPEC_FOLDER.glob("*.yaml"))
    for figure in FIGURES.values():
        assert figure.header("Paper") and figure.header("Claim"), figure.name


@pytest.mark.parametrize("scale", SCALES)
def test_every_figure_parses_and_plans_at_every_scale(scale):
    for figure in FIGURES.values():
        for part in figure.files():
            spec = parse_spec(spec_data(figure, part, scale))
            assert spec.name.endswith(f"-{scale}")
            planned(
                spec
            )  # contexts drawn, trials planned (kept: the results page reads them again)


def test_the_small_scale_keeps_the_papers_schedule_and_cuts_the_budget():
    figure = FIGURES["optgap_cartpole"]
    paper, small = (spec_data(figure, "optgap_cartpole", s) for s in ("paper", "small"))
    assert paper["agent_options"] == {"total_timesteps": 100000, "context_selector": "round_robin"}
    assert small["agent_options"] == {"total_timesteps": 30000, "context_selector": "round_robin"}
    assert (paper["num_contexts"], small["num_contexts"]) == (64, 8)
    decided = [f.name for f in FIGURES.values() if f.decided_small]  # their small runs decide
    assert decided == [
        "baseline_lunarlander_visibility",
        "pb2_acrobot",
        "pb2_lunarlander",
        "pb2_pendulum",
    ]
    for name in decided:
        for part in FIGURES[name].files():
            assert spec_data(FIGURES[name], part, "small")["seeds"] == MIN_SEEDS


def test_a_claim_holds_only_when_its_interval_clears_the_bound():
    assert _decide(Interval(5.0, 1.0, 9.0)) is True
    assert _decide(Interval(-5.0, -9.0, -1.0)) is False
    assert _decide(Interval(1.0, -1.0, 3.0)) is None
    assert _decide(Interval(31.0, 29.0, 33.0), 30.0) is None
    assert _all([True, True]) is True
    assert _all([True, None]) is None
    assert _all([None, False]) is False


@pytest.fixture(scope="module")
def paper_runs(tmp_path_factory):
    return tmp_path_factory.mktemp("paper")


# Figures run with the paper's agents on JAX environments, mostly compiling (the agents' host paths
# run in experiments/test_matrix.py: C51 on LunarLander in three protocols, DQN in visibility).
# Every other figure runs end to end with the random agent below, except the PB2 figures, which need
# an agent with hyper-parameters and a local Ray (minutes each on two cores): their specs parse and
# plan above, and PB2 itself runs in experiments/test_hpo.py.
WITH_THEIR_AGENTS = [
    "tabular_cmdp",
    "optgap_cartpole",
    "ecdf_pendulum",
    "baseline_mountaincar_default",
]
PB2_PARSED_ONLY = ["pb2_acrobot", "pb2_lunarlander", "pb2_pendulum"]


@pytest.mark.parametrize("name", WITH_THEIR_AGENTS)
def test_figures_run_end_to_end_with_their_agents_at_the_tiny_budget(name, paper_runs):
    verdict, report = run_figure(name, "tiny", root=paper_runs, progress=False)
    assert verdict.holds in (True, False, None) and verdict.evidence
    text = report.read_text()
    assert html.escape(FIGURES[name].header("Claim").split(":")[0][:40]) in text
    assert html.escape(verdict.sentence()) in text


def random_agent_specs(figure) -> dict[str, dict]:
    """Each part's tiny spec with the random agent in place of the figure's (its options dropped)."""
    specs = {}
    for part in figure.files():
        data = {**spec_data(figure, part, "tiny"), "agent": "random"}
        data.pop("agent_options", None)
        specs[part] = data
    return specs


def distinct_random_agent_runs(names: list[str]) -> list[str]:
    """``names`` less any figure whose random-agent runs equal an earlier one's but for their names:
    figures that differ only in their agent's options (DmcWalker's visibility figures) are one run."""
    seen, kept = [], []
    for name in names:
        specs = random_agent_specs(FIGURES[name])
        unnamed = [{k: v for k, v in data.items() if k != "name"} for data in specs.values()]
        if unnamed not in seen:
            seen.append(unnamed)
            kept.append(name)
    return kept


@pytest.mark.parametrize(
    "name",
    distinct_random_agent_runs(
        [n for n in FIGURES if n not in WITH_THEIR_AGENTS + PB2_PARSED_ONLY]
    ),
)
def test_every_other_figure_runs_end_to_end_with_a_random_agent(name, tmp_path):
    """The figure's environment, contexts, visibility variants and protocol at the tiny budget, its
    claim checked; the agent acts at random (training each figure's agent here is a minute of
    compiling per figure; the agents train in their own tests and in the figures above)."""
    figure = FIGURES[name]
    runs = {}
    for part, data in random_agent_specs(figure).items():
        runs[part], _ = run_experiment(data, out=tmp_path / part, progress=False, report=False)
    verdict = figure.check(runs)
    assert verdict.holds in (True, False, None) and verdict.evidence


def test_the_verdicts_of_the_tiny_runs_are_what_their_returns_give(paper_runs):
    """Tiny runs have 2 seeds: no verdict, whatever the intervals say, and the page says why.
    Episodes of at most 20 steps earn CartPole returns of at most 20, so every interval of the gap
    lies below 30: the rule alone would say "does not hold". MountainCar's 20-step episodes never
    reach the flag: trained and random agents both earn -20, shown beside the evidence. The paper's
    3-state cMDP is solved exactly (no seeds, no gate): its gap of 3 decides."""
    untrained, _ = run_figure(
        "baseline_mountaincar_default", "tiny", root=paper_runs, progress=False
    )
    assert untrained.word == "no verdict"
    assert untrained.withheld == (
        "2 seeds, fewer than 5; the agent did not learn at this budget: hidden"
    )
    assert "trained vs random return at the training contexts: hidden -20 vs -20" in (
        untrained.evidence
    )
    gap, _ = run_figure("optgap_cartpole", "tiny", root=paper_runs, progress=False)
    assert gap.word == "no verdict" and gap.holds is False
    assert "(95% CI; each needs to lie above 30)" in gap.evidence
    exact, _ = run_figure("tabular_cmdp", "tiny", root=paper_runs, progress=False)
    assert (
        exact.holds is True and exact.word == "reproduced" and "3-state cMDP: 3;" in exact.evidence
    )
    for name in ("tabular_cmdp", "optgap_cartpole", "baseline_mountaincar_default"):
        assert check_report(paper_runs / f"{name}-tiny" / name) > 0  # tables = results
    manifest = RunDir(paper_runs / "tabular_cmdp-tiny" / "tabular_cmdp").manifest()
    cores = len(os.sched_getaffinity(0))  # the cores the run could use, as `taskset` leaves them
    assert manifest["paper_machine"].startswith(f"{cores} CPU core{'s' if cores > 1 else ''}")
    assert manifest["paper_machines"] == [manifest["paper_machine"]]  # on the page
    # the plan `paper run` prints first: chunks finished and steps left, from the run's own files
    gap_run = RunDir(paper_runs / "optgap_cartpole-tiny" / "optgap_cartpole")
    plan = planned(gap_run.spec())
    steps = f"{training_steps(gap_run.spec()):,}"
    figure = FIGURES["optgap_cartpole"]
    assert (
        f"optgap_cartpole: {len(plan.trials)} trials in {len(plan.chunks)} chunk(s) of up to "
        f"{gap_run.spec().batch_size}, {len(plan.chunks)} finished; 0 of {steps} training steps "
        "left\n  time left: nothing left to train"
    ) in plan_text(figure, "tiny", paper_runs)
    fresh = plan_text(figure, "tiny", paper_runs / "elsewhere", batch_size=1)
    assert f"{len(plan.trials)} chunk(s) of up to 1, 0 finished; {steps} of {steps}" in fresh
    assert "time left: not estimated (no finished run of these agents)" in fresh
    # a host environment trains a chunk's trials one after another: each its own chunk by default
    walker = plan_text(FIGURES["visibility_dmcwalker"], "paper", paper_runs / "elsewhere")
    assert "15 trials in 15 chunk(s) of up to 1, 0 finished" in walker, walker
    # a full-budget run stopped part-way: the page says how far it got (its chunks on disk)
    partial = paper_runs / "partial" / "optgap_cartpole-paper"
    shutil.copytree(gap_run.path.parent, partial)
    (partial / "optgap_cartpole" / "results" / "chunk-0001.parquet").unlink()
    section = results_page(partial.parent).split("## optgap_cartpole\n")[1].split("\n## ")[0]
    assert (
        f"- **At the authors' budget**: under way, 1 of {len(plan.chunks)} chunks finished and kept"
        in section
    )
    assert "at the pace of its finished chunks" in section  # its own budget's pace, not another's
    # its general agents are trained, so the specialists to come are bounded by the 20 an episode
    # of 20 steps can return: the intervals are already below 30, and the finished run's never
    # exceed those bounds (the same bootstrap draws; mean, median and IQM never fall as a return rises)
    settled = figure.check.settled({"optgap_cartpole": RunDir(partial / "optgap_cartpole")})
    assert settled.holds is False and settled.withheld.startswith("2 seeds, fewer than 5")
    untrained = len(plan.chunks[1])
    assert f"even if each of the {untrained} specialists not yet trained returned 20 " in (
        settled.evidence
    )
    assert (
        "Whatever the unfinished chunks give, its intervals would say *not reproduced*" in section
    )
    # the same at the small budget, where nothing has finished: it replaces "Not run yet"
    small = paper_runs / "partial-small" / "optgap_cartpole-small"
    shutil.copytree(partial, small)
    section = results_page(small.parent).split("## optgap_cartpole\n")[1].split("\n## ")[0]
    assert (
        f"- **At the small budget**: under way, 1 of {len(plan.chunks)} chunks finished and kept "
        "(`optgap_cartpole-small`; the same command carries it on); time left: ≈ "
    ) in section
    assert "Not run yet" not in section
    bound, final = _differences(settled.evidence), _differences(gap.evidence)
    assert set(final) == {"mean", "median", "IQM"} and set(bound) == set(final)
    assert all(final[name][2] <= bound[name][2] for name in final), (final, bound)


def test_a_run_under_way_has_no_verdict_once_an_agent_with_every_seed_trained_did_not_learn(
    tmp_path,
):
    """The gate is on each variant's mean over its seeds: once every seed of one variant has trained
    without beating a random policy, no unfinished chunk can give the figure a verdict, and the page
    says so. The DmcWalker figure's paper spec (a chunk per trial, hidden's five seeds first), its
    returns written by hand: a random policy's 20 at every training context."""
    figure = FIGURES["visibility_dmcwalker"]
    # a chunk per trial, as `paper run` plans a host figure
    spec = parse_spec({**spec_data(figure, figure.name, "paper"), "batch_size": 1})
    run = RunDir.create(spec, out=tmp_path / f"{figure.name}-paper" / figure.name)
    plan = planned(spec)

    def finish(chunk: int, train_return: float) -> None:
        (trial,) = (plan.trials[i] for i in plan.chunks[chunk])
        row = {**trial_columns(trial), "train_return": train_return, "random_return": 20.0}
        write_parquet(run.path / "training" / f"chunk-{chunk:04d}.parquet", pd.DataFrame([row]))
        tested = {**trial_columns(trial), "test_set": trial.test_set, "context_index": 0}
        write_parquet(
            run.path / "results" / f"chunk-{chunk:04d}.parquet",
            pd.DataFrame([{**tested, "return": train_return}]),
        )
        run.record_timing(chunk, 60.0)

    for chunk in range(4):
        finish(chunk, 19.0 + chunk % 2)  # hidden, seeds 0-3
    assert [plan.trials[i].variant for i in plan.chunks[4]] == ["hidden"]
    assert figure.check.settled({figure.name: run}) is None  # seed 4 could still lift the mean
    finish(4, 40.0)  # mean 23.6 against 20: hidden learned, the other variants to come
    assert figure.check.settled({figure.name: run}) is None
    finish(4, 25.0)  # mean 20.6: short of 20 + 10% of 20
    settled = figure.check.settled({figure.name: run})
    assert settled.word == "no verdict" and settled.gate_only
    assert settled.withheld == "the agent did not learn at this budget: hidden"
    assert "hidden 20.6 vs 20, over 5 seeds each, all trained" in settled.evidence
    section = results_page(tmp_path).split(f"## {figure.name}\n")[1].split("\n## ")[0]
    assert "under way, 5 of 15 chunks finished and kept" in section
    assert (
        "**Already no verdict** (the agent did not learn at this budget: hidden), whatever the "
        "unfinished chunks give: trained vs random return at the training contexts: hidden 20.6 vs "
        "20, over 5 seeds each"
    ) in section


def test_a_figure_whose_full_budget_does_not_fit_is_decided_at_the_small_budget(tmp_path):
    """PB2 on Acrobot: a kept small run of 3 PB2 runs per arm gets the catalogue's 5 (its 3 stay),
    and the small run, finished, decides, its budget stated as the deviation. The best members'
    returns written by hand: hidden -100 + seed, visible -300 + seed, a random policy's -500."""
    figure = FIGURES["pb2_acrobot"]
    assert figure.decided_small
    runs = {}
    for part, base in (("hidden", -100.0), ("visible", -300.0)):
        spec = parse_spec({**spec_data(figure, part, "small"), "seeds": 3})
        runs[part] = RunDir.create(spec, out=tmp_path / "pb2_acrobot-small" / part)
        runs[part].update_manifest(paper_machine="2 CPU cores")  # as `paper run` records it
        for chunk in range(3):
            _write_chunk(runs[part], planned(spec), chunk, base + chunk, -500.0)
        _add_catalogue_seeds(figure, part, "small", runs[part], progress=False)
        assert runs[part].spec().seeds == MIN_SEEDS and runs[part].finished() == {0, 1, 2}
    section = results_page(tmp_path).split("## pb2_acrobot\n")[1].split("\n## ")[0]
    assert "- **At the small budget**: under way, 6 of 10 chunks finished and kept" in section
    for part, base in (("hidden", -100.0), ("visible", -300.0)):
        for chunk in (3, 4):
            _write_chunk(runs[part], planned(runs[part].spec()), chunk, base + chunk, -500.0)
    section = results_page(tmp_path).split("## pb2_acrobot\n")[1].split("\n## ")[0]
    assert (
        "- **At the small budget, which decides here** (hidden: 5 PB2 runs × 4 agents × 40,000 "
        "steps each"
    ) in section
    assert (
        "a deviation: the full budget does not fit two CPU cores, see below): **reproduced** (the "
        "margin is the library's: *reproduced* at half of it, *reproduced* at it, *reproduced* at "
        "twice it). mean test return hidden − concat_all = 200 ["
    ) in section
    assert "hidden -98, concat_all -298; trained vs random return" in section  # -100 + 0..4
    assert (
        "On a Ray cluster, from one of its machines: `contextrl paper run pb2_acrobot --scale "
        "paper --executor ray --address auto`"
    ) in section


def _write_chunk(run: RunDir, plan, chunk: int, value: float, random: float) -> None:
    """A finished chunk written by hand: its trials return ``value`` at every test context."""
    for index in plan.chunks[chunk]:
        trial = plan.trials[index]
        row = {**trial_columns(trial), "train_return": value, "random_return": random}
        write_parquet(run.path / "training" / f"chunk-{chunk:04d}.parquet", pd.DataFrame([row]))
        tested = [
            {
                **trial_columns(trial),
                "test_set": trial.test_set,
                "context_index": i,
                "return": value,
            }
            for i in range(len(plan.sets[trial.test_set]))
        ]
        write_parquet(run.path / "results" / f"chunk-{chunk:04d}.parquet", pd.DataFrame(tested))
        run.record_timing(chunk, 60.0)


def test_the_rate_comes_from_runs_of_the_same_agent_settings_first(tmp_path):
    """DmcWalker's SAC with the authors' settings and with CleanRL's cost several times apart per
    step: the paper run's estimate takes the kept run of its own settings, and another settings' run
    only where none of its own has finished. A run under way counts the steps of its finished
    chunks, which its time was spent on. (The run of the authors' settings is the kept CleanRL run
    with the authors' agent options written into its spec: a stand-in whose timings differ.)"""
    kept, names = ROOT / PAPER_RUNS, ("visibility_dmcwalker", "visibility_dmcwalker_cleanrl")
    source = kept / f"{names[1]}-small" / names[1]
    runs = []
    for figure in names:
        folder = tmp_path / f"{figure}-small" / figure
        shutil.copytree(source, folder)
        runs.append(RunDir(folder))
    own, other = runs
    data = yaml.safe_load((source / "spec.yaml").read_text(encoding="utf-8"))
    data["agent_options"] = spec_data(FIGURES[names[0]], names[0], "small")["agent_options"]
    (own.path / "spec.yaml").write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    own.update_manifest(wall_seconds=2 * wall_seconds(other))
    paper = [parse_spec(spec_data(FIGURES[names[0]], names[0], "paper"))]
    rate, _ = seconds_per_step(paper, "paper", tmp_path)
    assert rate == wall_seconds(own) / training_steps(own.spec())
    (own.path / "results" / "chunk-0000.parquet").unlink()  # as if stopped before its last chunk
    plan = planned(own.spec())
    left = own.spec().training_steps([plan.trials[i] for i in plan.chunks[0]])
    rate, _ = seconds_per_step(paper, "paper", tmp_path)
    assert rate == wall_seconds(own) / (training_steps(own.spec()) - left)
    shutil.rmtree(own.path)
    rate, _ = seconds_per_step(paper, "paper", tmp_path)
    assert rate == wall_seconds(other) / training_steps(other.spec())


def test_the_page_names_the_cpu_model_of_every_machine_a_run_trained_on(tmp_path):
    """Linux's model name and widest vector unit, from /proc/cpuinfo's first processor; a run
    resumed elsewhere lists both machines, and one kept before machines were listed its last."""
    cpuinfo = tmp_path / "cpuinfo"
    first = "model name\t: AMD EPYC\nflags\t\t: fpu sse2 avx avx2\n\n"
    cpuinfo.write_text(first + "model name\t: other\nflags\t\t: avx512f\n", encoding="utf-8")
    assert cpu_model(cpuinfo) == "AMD EPYC with AVX2"
    cpuinfo.write_text("model name\t: Intel Xeon\nflags\t\t: avx2 avx512f\n", encoding="utf-8")
    assert cpu_model(cpuinfo) == "Intel Xeon with AVX-512"
    cpuinfo.write_text("processor\t: 0\n", encoding="utf-8")
    assert cpu_model(cpuinfo) == ""
    spec = parse_spec(spec_data(FIGURES["tabular_cmdp"], "tabular_cmdp", "tiny"))
    both, old = (RunDir.create(spec, out=tmp_path / name) for name in ("both", "old"))
    jax_version = both.manifest()["versions"]["jax"]
    both.update_manifest(
        paper_machine="1 CPU core, B", paper_machines=["1 CPU core, A", "1 CPU core, B"]
    )
    old.update_manifest(paper_machine="2 CPU cores")
    assert machines([both, old]) == (
        f"1 CPU core, A (JAX {jax_version}) and 1 CPU core, B (JAX {jax_version}) and "
        f"2 CPU cores (JAX {jax_version})"
    )


def test_pb2_members_count_as_an_agent_of_their_own():
    """A PB2 population's members train one to a process, not vmapped: their rate is not that of
    the same agent in another protocol."""
    pb2 = parse_spec(spec_data(FIGURES["pb2_acrobot"], "hidden", "paper"))
    baseline = parse_spec(
        spec_data(FIGURES["baseline_acrobot_visibility"], "baseline_acrobot_visibility", "paper")
    )
    assert (pb2.env, pb2.agent) == ("Acrobot", "dqn") and baseline.env == "Acrobot"
    assert _agent_settings(pb2)[1] == "dqn in PB2" and _agent_settings(baseline)[1] == "c51"


def _differences(evidence: str) -> dict[str, tuple[float, float, float]]:
    """The specialists − general intervals a gap verdict states: {statistic: (point, low, high)}."""
    stated = evidence.split("(95% CI")[0]
    found = re.findall(r"(mean|median|IQM) (\S+) \[(\S+), (\S+)\]", stated)
    return {name: tuple(float(v) for v in values) for name, *values in found}


def test_every_spec_states_the_decision_rule_its_check_applies():
    """The rule in each spec file (written before its runs) is the one the page prints and the
    check applies: both come from the same text, so they cannot drift apart."""
    for figure in FIGURES.values():
        for part in figure.files():
            assert figure.header("Decision", part) == figure.rule, (figure.name, part)
        if figure.check.gated:
            assert figure.rule.endswith(GATE)
        assert figure.header("Budget"), figure.name
    stated = {f.name for f in FIGURES.values() if f.stated_budget}
    chosen = {
        "tabular_cmdp",
        "platformer_conditioning",
        *(f for f in FIGURES if f.startswith("pb2")),
    }
    assert stated == set(FIGURES) - chosen, stated ^ (set(FIGURES) - chosen)


def test_sensitivity_zones_and_equivalence_margins_are_fixed_fractions_of_the_gain():
    gain = 200.0  # harmless below 20, brittle above 100
    assert _zone(Interval(5.0, 0.0, 19.0), gain) == "harmless"
    assert _zone(Interval(50.0, 21.0, 99.0), gain) == "moderate"
    assert _zone(Interval(150.0, 101.0, 300.0), gain) == "brittle"
    assert _zone(Interval(20.0, 10.0, 30.0), gain) is None  # straddles a boundary: undecided
    assert (HARMLESS, BRITTLE, EQUIVALENCE, MIN_SEEDS) == (0.10, 0.50, 0.10, 5)


def test_every_kept_run_was_trained_with_the_settings_its_spec_gives_today():
    """A kept run records the agent settings it trained with; a changed default (an agent's
    ``paper_config``, a field added) that would train its spec differently today fails here, so the
    page never shows a run under settings it was not trained with: rerun it or remove it."""
    kept = sorted((ROOT / PAPER_RUNS).glob("*/*/spec.yaml"))
    assert kept
    for spec_file in kept:
        run = RunDir(spec_file.parent)
        recorded = run.manifest().get("agent_settings")
        assert recorded is not None, f"{run.path}: no agent settings recorded"
        assert recorded == agent_settings(run.spec()), f"{run.path}: trained with other settings"


def test_the_docs_results_page_is_what_the_kept_runs_give(monkeypatch):
    """docs/paper.md is generated, never edited: `contextrl paper page` writes it word for word from
    the run records kept in results/paper, so a changed check, budget or claim, a run added or a
    hand edit without regenerating the page fails here."""
    monkeypatch.chdir(ROOT)
    page = Path("docs/paper.md").read_text(encoding="utf-8")
    assert page == results_page(PAPER_RUNS) + "\n", "regenerate it: contextrl paper page"
    for name in FIGURES:
        assert f"## {name}\n" in page
    assert CAUSES in page and MARGIN_RULE.split(": ")[1] in page
    tabular = page.split("## tabular_cmdp\n")[1].split("\n## ")[0]
    assert "**Solved exactly** (exact solution; " in tabular and "): **reproduced**." in tabular
    # a full budget not run here: its time at the measured rate, and the commands that run it
    # elsewhere (a GPU machine only for a JAX environment's trials, vmapped together)
    gap = page.split("## optgap_pendulum\n")[1].split("\n## ")[0]
    assert "--scale paper --executor ray --address auto" in gap
    assert "contextrl paper run optgap_pendulum --scale paper --batch-size 650" in gap
    # CartPole's agents near the 500 an episode can return: the ceiling is the cause named
    visibility = page.split("## baseline_cartpole_visibility\n")[1].split("\n## ")[0]
    assert "(most likely cause: hidden at the return ceiling (its mean test return " in visibility
    walker = page.split("## visibility_dmcwalker\n")[1].split("\n## ")[0]
    assert "from runs of other agent settings (" in walker and "per training step)" in walker
    assert "--batch-size" not in walker  # dm_control steps on the host
    for name in ("baseline_cartpole_default", "platformer_conditioning"):
        section = page.split(f"## {name}\n")[1].split("\n## ")[0]
        full = "the authors' budget" if FIGURES[name].stated_budget else "full budget"
        assert f"- **At {full}** (" in section and "over seeds" in section


def test_the_command_lists_figures_and_refuses_an_unknown_one(capsys, tmp_path):
    assert main(["paper", "list", "--runs", str(tmp_path)]) == 0
    listed = capsys.readouterr().out
    assert all(f"{name}  (" in listed for name in FIGURES)
    assert main(["paper", "run", "figure_9", "--runs", str(tmp_path)]) == 2
    assert "unknown figure 'figure_9'; choose one of ['tabular_cmdp'" in capsys.readouterr().err


def test_paper_page_refuses_a_runs_folder_that_does_not_exist(capsys, tmp_path):
    """Before: ``paper page --runs MISSING`` wrote a page with every figure "not run"."""
    out = tmp_path / "paper.md"
    missing = tmp_path / "MISSING_DIR"
    for action in ("page", "list"):
        assert main(["paper", action, "--runs", str(missing), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert err == (
            f"contextrl paper: error: paper {action}: --runs {missing} is not a folder; give the "
            "folder `contextrl paper run --runs` wrote (default ./results/paper)"
        )
    assert not out.exists()
    missing_folder = tmp_path / "no" / "paper.md"  # refused before the page reads any run
    assert main(["paper", "page", "--runs", str(tmp_path), "--out", str(missing_folder)]) == 2
    assert f"--out {missing_folder}: no folder {missing_folder.parent}" in capsys.readouterr().err
    afile = tmp_path / "afile"
    afile.write_text("")
    assert main(["paper", "run", "tabular_cmdp", "--runs", str(afile)]) == 2
    assert f"--runs {afile} is a file; give a folder" in capsys.readouterr().err


def test_a_withheld_verdict_reads_as_a_sentence(capsys, tmp_path, monkeypatch):
    """Before: ``paper run ecdf_pendulum --scale tiny`` printed "the claim no verdict"; and the help
    said the tiny scale decides nothing while an exactly solved claim is decided there."""
    from contextrl.paper import command

    withheld = Verdict(True, "drops ...", "2 seeds, fewer than 5")
    monkeypatch.setattr(command, "run_figure", lambda *a, **k: (withheld, tmp_path / "paper.html"))
    assert main(["paper", "run", "ecdf_pendulum", "--scale", "tiny", "--runs", str(tmp_path)]) == 0
    printed = capsys.readouterr().out.splitlines()[0]
    assert printed == (
        "ecdf_pendulum (tiny budget): no verdict on the claim (2 seeds, fewer than 5). drops ...."
    )
    assert Verdict(None, "e").sentence("**") == "**undecided**"
    with pytest.raises(SystemExit):
        main(["paper", "--help"])
    assert "a claim solved exactly is decided at every scale" in " ".join(
        capsys.readouterr().out.split()
    )


def test_verdicts_read_as_reproductions():
    """Each state in the reproduction's words: a claim not reproduced says at what budget and
    settings and names its likely cause; a withheld verdict says why."""
    assert Verdict(True, "e").sentence("**") == "**reproduced**"
    assert Verdict(None, "e").sentence() == "undecided"
    failed = Verdict(False, "e", at="1,000 training steps", cause="a substituted agent")
    assert failed.word == "not reproduced"
    assert failed.sentence() == (
        "not reproduced at 1,000 training steps (most likely cause: a substituted agent)"
    )
    withheld = Verdict(False, "e", "3 seeds, fewer than 5")
    assert withheld.word == "no verdict"
    assert withheld.sentence() == "no verdict on the claim (3 seeds, fewer than 5)"


class _Scores:
    matrix = np.zeros((1, 1))


@pytest.mark.parametrize(
    ("check", "interval", "margins", "word"),
    [
        # better: reproduced above 0, not reproduced below 10 % of the gain of 200 (20)
        (better_check("a", "b"), (5.0, -5.0, 15.0), (None, False, False), "undecided"),
        (better_check("a", "b"), (5.0, -5.0, 8.0), (False, False, False), "not reproduced"),
        (better_check("a", "b"), (5.0, 1.0, 8.0), (True, True, True), "reproduced"),
        # no difference: reproduced inside ± 20, not reproduced outside it
        (similar_check("a", "b"), (0.0, -15.0, 15.0), (None, True, True), "undecided"),
        (similar_check("a", "b"), (0.0, -8.0, 8.0), (True, True, True), "reproduced"),
        (similar_check("a", "b"), (60.0, 50.0, 70.0), (False, False, False), "not reproduced"),
    ],
)
def test_a_verdict_that_changes_between_half_and_twice_the_librarys_margin_is_undecided(
    check, interval, margins, word, monkeypatch
):
    """The rule applied at half, at and at twice its margin (a fraction of the gain the library
    chose, not the paper) to the same interval: where the three differ the verdict is undecided,
    else it is theirs; the page shows all three."""
    scores = {"a": _Scores(), "b": _Scores()}
    monkeypatch.setattr(
        checks, "_variant_difference", lambda runs, a, b: (scores, Interval(*interval), "seeds")
    )
    verdict = check.decide({}, 200.0)
    assert verdict.margins == margins and verdict.word == word
    assert "The margin is the library's, not the paper's" in check.rule
    assert f"*{checks.WORDS[margins[0]]}* at half of it" in verdict.sentence("**")
    assert ("undecided, as the verdict changes across them" in verdict.sentence()) == (
        len(set(margins)) > 1
    )


def test_the_sensitivity_zones_scale_with_the_margin():
    gain = 200.0  # harmless below 20, brittle above 100; at half: 10 and 50; at twice: 40, 200
    drop = Interval(30.0, 25.0, 35.0)
    assert [_zone(drop, gain, scale) for scale in (0.5, 1.0, 2.0)] == [
        "moderate",
        "moderate",
        "harmless",
    ]
    assert _zone(Interval(60.0, 55.0, 65.0), gain, 0.5) == "brittle"


def _not_reproduced(name: str) -> PaperFigure:
    """Figure ``name`` with a check that finds its claim not reproduced, as a constructed result."""
    return dataclasses.replace(
        FIGURES[name], check=Check("rule", lambda runs, gain: Verdict(False, "e"), gated=False)
    )


@pytest.mark.parametrize(
    ("name", "cause"),
    [
        ("pb2_pendulum", "a substituted agent (the settings say which, and why)"),
        ("platformer_conditioning", "the budget, chosen here (the budget line says why)"),
        (
            "kirk_cartpole",
            "a budget below the authors' ({small:,} of their {paper:,} training steps)",
        ),
    ],
)
def test_a_claim_not_reproduced_names_its_budget_settings_and_most_likely_cause(
    name, cause, tmp_path
):
    """The first cause the runs show, by the rule the page states: a substituted agent where the
    settings say so (PB2 on Pendulum runs SAC for DDPG); else the budget, below the authors' where
    the spec records theirs (Kirk's CartPole: 100,000 steps) and else chosen here (the platformer's
    PPO, which the authors' configs do not train)."""
    figure = _not_reproduced(name)
    runs = {
        part: RunDir.create(parse_spec(spec_data(figure, part, "small")), out=tmp_path / part)
        for part in figure.files()
    }
    steps = {
        scale: sum(training_steps(parse_spec(spec_data(figure, p, scale))) for p in runs)
        for scale in ("paper", "small")
    }
    verdict = figure.verdict(runs)
    agent = runs[next(iter(runs))].spec().agent
    seeds = runs[next(iter(runs))].spec().seeds
    assert verdict.at == (
        f"{steps['small']:,} training steps, {seeds} seeds and the settings stated ({agent})"
    )
    assert verdict.cause == cause.format(**steps)
    assert verdict.sentence().endswith(f"(most likely cause: {verdict.cause})")


def test_a_gap_not_reproduced_at_the_return_ceiling_names_it(monkeypatch):
    """CartPole's general agent at the 500 an episode can return leaves no room for specialists 30
    better: that is the cause named, before any budget or setting (constructed statistics)."""
    spec = parse_spec(spec_data(FIGURES["optgap_cartpole"], "optgap_cartpole", "small"))
    at_ceiling = Interval(0.0, -1.0, 5.0)
    stats = types.SimpleNamespace(
        general=types.SimpleNamespace(matrix=np.full((3, 8), 500.0)),
        differences={"mean": at_ceiling, "median": at_ceiling, "IQM": at_ceiling},
        finished={},
        improvement=Interval(0.5, 0.4, 0.6),
        per_seed=lambda: {"general": [500.0], "specialists": [500.0]},
    )
    monkeypatch.setattr(checks, "_cells", lambda run: (spec, None))
    monkeypatch.setattr(checks, "gap_statistics", lambda *a, **k: {spec.variants[0]: stats})
    verdict = gap_check(30.0, most_per_step=1.0).decide({"optgap_cartpole": None}, 400.0)
    assert verdict.holds is False and not verdict.margins  # the paper's own margin
    assert verdict.cause == (
        "the general agent at the return ceiling (its IQM test return 500 of at most 500), which "
        "leaves the specialists no room to beat it by 30"
    )
    stats.general.matrix = np.full((3, 8), 400.0)
    assert gap_check(30.0, most_per_step=1.0).decide({"optgap_cartpole": None}, 400.0).cause == ""
