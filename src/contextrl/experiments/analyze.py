"""Turn a run directory into report sections: statistics with CIs, figures and tables per protocol."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pandas as pd
import yaml

from contextrl.analysis import metrics, plots
from contextrl.analysis.intervals import (
    Interval,
    interval_estimates,
    paired_bootstrap_ci,
)
from contextrl.analysis.report import Figure, Section, render
from contextrl.experiments.protocols import REGIONS, Plan, expand
from contextrl.experiments.runs import RunDir, write_text
from contextrl.experiments.spec import CommonSpec, spec_to_dict
from contextrl.experiments.tabular import random_cmdp, solve, three_state_cmdp

CI_METRICS = {
    "mean": metrics.aggregate_mean,
    "median": metrics.aggregate_median,
    "IQM": metrics.aggregate_iqm,
}


def score_matrix(frame: pd.DataFrame) -> np.ndarray:
    """Returns as (seeds × contexts) for one agent kind/variant."""
    table = frame.pivot_table(
        index="seed", columns="context_index", values="return", aggfunc="mean"
    )
    return table.dropna(axis=0).to_numpy()


def _interval_rows(results: dict[str, dict[str, Interval]]) -> list[dict]:
    return [
        {"agent": name, **{metric: str(interval) for metric, interval in row.items()}}
        for name, row in results.items()
    ]


def _figure(name: str, figure, caption: str) -> Figure:
    return Figure(name, plots.to_png(figure), caption)


def environment_section(spec: CommonSpec) -> Section:
    """A radar of the run's environment next to the others of its family."""
    import contextrl as crl

    family = crl.spec(spec.env).family
    properties = {}
    for env_id in crl.registered(family):
        if crl.spec(env_id).host:
            continue
        env = crl.make(env_id)
        features = env.context_space.features.values()
        action = env.action_space
        properties[env_id] = {
            "actions": getattr(action, "n", None) or int(np.prod(action.shape)),
            "observation size": int(np.prod(env.base_observation_space.shape)),
            "features": len(features),
            "change dynamics": sum("dynamics" in f.affects for f in features),
            "change reward": sum("reward" in f.affects for f in features),
            "change start/goal": sum(
                bool({"start_state", "goal"} & set(f.affects)) for f in features
            ),
        }
    rows = [{"environment": name, **values} for name, values in properties.items()]
    figure = _figure(
        "environment-radar",
        plots.radar(properties, title=f"{family} environments"),
        "Environment properties (each axis scaled by its largest value)",
    )
    return Section("Environment", tables=[("Environment properties", rows)], figures=[figure])


def sensitivity_sections(spec, plan: Plan, results: pd.DataFrame) -> list[Section]:
    returns = {
        feature: {m: group["return"].to_numpy() for m, group in by_feature.groupby("magnitude")}
        for feature, by_feature in results.groupby("feature", sort=False)
    }
    rows = []
    for feature, by_magnitude in returns.items():
        means = {m: float(np.mean(v)) for m, v in by_magnitude.items()}
        worst = min(means, key=means.get)
        rows.append(
            {
                "feature": feature,
                "return at A=1": means.get(1.0, math.nan),
                "worst A": worst,
                "return at worst A": means[worst],
                "mean over A": float(np.mean(list(means.values()))),
            }
        )
    figure = _figure(
        "sensitivity-ecdf",
        plots.sensitivity_ecdfs(returns, title=f"{spec.env}: agent trained on the default context"),
        "eCDF of test returns per feature; A is the magnitude multiplied with the default value",
    )
    text = [
        f"A {spec.agent} agent trained on the default context (hidden), evaluated with each feature "
        f"scaled by A ∈ {list(spec.magnitudes)} × default; {spec.seeds} seeds × "
        f"{spec.eval_episodes} episodes per context. Magnitudes outside a feature's bounds are skipped."
    ]
    return [Section("Sensitivity", text, [("Return per feature", rows)], [figure])]


def optimality_gap_sections(spec, plan: Plan, results: pd.DataFrame) -> list[Section]:
    general = results[results["kind"] == "general"]
    specialists = results[results["kind"] == "specialist"]
    sections = []
    for variant in spec.variants:
        g = general[general["variant"] == variant]
        s = specialists[specialists["variant"] == variant].copy()
        if g.empty or s.empty:
            continue
        s["context_index"] = s["context"]
        g_scores, s_scores = score_matrix(g), score_matrix(s)
        if g_scores.shape[1] != s_scores.shape[1]:
            continue  # some specialists are still missing (unfinished or failed chunks)
        cis = interval_estimates(
            {"general": g_scores, "specialists": s_scores},
            CI_METRICS,
            reps=spec.bootstrap_reps,
            seed=spec.seed,
        )
        gap = paired_bootstrap_ci(
            g_scores,
            s_scores,
            metrics.context_optimality_gap,
            reps=spec.bootstrap_reps,
            seed=spec.seed,
        )
        improvement = paired_bootstrap_ci(
            s_scores,
            g_scores,
            metrics.probability_of_improvement,
            reps=spec.bootstrap_reps,
            seed=spec.seed,
        )
        best = float(max(g_scores.max(), s_scores.max()))
        solved = {
            "general": metrics.fraction_solved(g_scores, 0.99 * best),
            "specialists": metrics.fraction_solved(s_scores, 0.99 * best),
        }
        per_context = metrics.per_context_gap(g_scores, s_scores)
        varying = plan.spec.space().varying(plan.sets["train"].contexts)
        feature = varying[0] if varying else None
        rows = _interval_rows(cis)
        for row in rows:
            row["fraction at best return"] = solved[row["agent"]]
        text = [
            f"Variant {variant}: one general agent trained on {spec.num_contexts} contexts vs one "
            f"specialist per context; each evaluated on the context(s) it was trained on "
            f"({spec.eval_episodes} episodes, {spec.seeds} seeds). 95% stratified-bootstrap CIs "
            f"({spec.bootstrap_reps} replicates, seed {spec.seed}).",
            f"Optimality gap E_c[G_specialist(c) − G_general(c)] = {gap}.",
            f"Probability that a specialist beats the general agent on a context: {improvement}.",
            f"Fraction of run×context returns at the best return observed in the run ({best:g}): "
            f"general {solved['general']:.2f}, specialists {solved['specialists']:.2f}.",
        ]
        figures = [
            _figure(
                f"optgap-ecdf-{variant}",
                plots.ecdf({"general": g_scores, "specialists": s_scores}, title="Return eCDF"),
                "eCDF of returns of the general agent and the specialists",
            ),
            _figure(
                f"optgap-intervals-{variant}",
                plots.intervals(cis, title="Aggregate return (95% CI)"),
                "Mean, median and IQM with stratified-bootstrap CIs",
            ),
        ]
        if feature is not None:
            values = np.asarray(getattr(plan.sets["train"].contexts, feature))
            figures.append(
                _figure(
                    f"optgap-per-context-{variant}",
                    plots.scatter(
                        values,
                        {"specialist − general": per_context},
                        xlabel=feature,
                        ylabel="return gap",
                        title="Gap per context",
                    ),
                    f"Per-context optimality gap against {feature}",
                )
            )
        sections.append(
            Section(f"Optimality gap ({variant})", text, [("Aggregates", rows)], figures)
        )
    if not sections:
        sections.append(Section("Optimality gap", ["Not enough finished trials for the gap."]))
    return sections


def _curves_by_variant(curves: pd.DataFrame) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    table = {}
    steps = np.sort(curves["step"].unique())
    for variant, group in curves.groupby("variant", sort=False):
        wide = group.pivot_table(index="trial", columns="step", values="episode_return")
        wide = wide.reindex(columns=steps).ffill(axis=1).bfill(axis=1).fillna(0.0)
        # a moving average over ~1/20 of training, so the band shows seeds, not update noise
        window = max(1, len(steps) // 20)
        table[variant] = wide.T.rolling(window, min_periods=1).mean().T.to_numpy()
    return steps, table


def visibility_sections(spec, plan: Plan, results: pd.DataFrame, curves: pd.DataFrame):
    scores = {
        variant: score_matrix(group) for variant, group in results.groupby("variant", sort=False)
    }
    cis = interval_estimates(scores, CI_METRICS, reps=spec.bootstrap_reps, seed=spec.seed)
    text = [
        f"{spec.agent} agents with context visibility {list(spec.variants)} trained on "
        f"{spec.num_train_contexts} contexts and tested on {spec.num_test_contexts} held-out contexts "
        f"({spec.seeds} seeds, {spec.eval_episodes} episodes each)."
    ]
    rows = _interval_rows(cis)
    if "hidden" in scores:
        for name, matrix in scores.items():
            if name != "hidden" and matrix.shape[1] == scores["hidden"].shape[1]:
                poi = paired_bootstrap_ci(
                    matrix,
                    scores["hidden"],
                    metrics.probability_of_improvement,
                    reps=spec.bootstrap_reps,
                    seed=spec.seed,
                )
                text.append(f"P({name} > hidden) = {poi}")
    figures = []
    if not curves.empty:
        steps, by_variant = _curves_by_variant(curves)
        figures.append(
            _figure(
                "training-curves",
                plots.training_curves(steps, by_variant, title="Training", seed=spec.seed),
                "Mean training return with a 95% bootstrap band over seeds",
            )
        )
    figures += [
        _figure("test-ecdf", plots.ecdf(scores, title="Test returns"), "eCDF of test returns"),
        _figure("test-histogram", plots.histograms(scores, title="Test returns"), "Test returns"),
        _figure(
            "test-intervals",
            plots.intervals(cis, title="Test return (95% CI)"),
            "Aggregate test return with stratified-bootstrap CIs",
        ),
    ]
    return [Section("Context visibility", text, [("Test return", rows)], figures)]


def train_test_sections(spec, plan: Plan, results: pd.DataFrame, curves: pd.DataFrame):
    train_box, _ = spec.boxes()
    (name_x, (x0, x1)), (name_y, (y0, y1)) = train_box.items()
    figures, rows = [], []
    top = float(results["return"].max())
    for mode in spec.modes:
        train = plan.sets[f"train-{mode}"].contexts
        points = np.stack(
            [np.asarray(getattr(train, name_x)), np.asarray(getattr(train, name_y))], axis=1
        )
        for variant in spec.variants:
            group = results[(results["kind"] == f"mode{mode}") & (results["variant"] == variant)]
            if group.empty:
                continue
            cells = group.groupby("context_index").agg(
                x=(f"ctx.{name_x}", "first"), y=(f"ctx.{name_y}", "first"), value=("return", "mean")
            )
            figures.append(
                _figure(
                    f"heatmap-{mode}-{variant}",
                    plots.heatmap(
                        cells["x"],
                        cells["y"],
                        cells["value"],
                        xlabel=name_x,
                        ylabel=name_y,
                        regions=[(x0, x1, y0, y1)],
                        train_points=points,
                        bins=int(np.sqrt(len(cells))),
                        title=f"mode {mode}, {variant}",
                        vmin=0.0,
                        vmax=top,
                    ),
                    f"Mean test return over the context plane, mode {mode}, {variant}; the red box is "
                    "the training range, red dots the training contexts",
                )
            )
            for region in REGIONS:
                subset = group[group["region"] == region]
                if subset.empty:
                    continue
                interval = interval_estimates(
                    {"r": score_matrix(subset)},
                    {"mean": metrics.aggregate_mean},
                    reps=spec.bootstrap_reps,
                    seed=spec.seed,
                )["r"]["mean"]
                rows.append(
                    {
                        "mode": mode,
                        "variant": variant,
                        "region": region,
                        "mean return": str(interval),
                    }
                )
    text = [
        f"Kirk et al.'s evaluation protocol over {name_x} × {name_y}: mode A trains on the whole box, "
        f"B on an L-shaped band ({spec.band:.0%} of each range) along its low edges, C on the two "
        "low edges only. Test contexts form a grid over the test box; each is labelled interpolation, "
        "combinatorial interpolation (inside the box, off the training support) or extrapolation in "
        "one or both features."
    ]
    sections = [
        Section("Train/test modes", text, [("Mean return per region (95% CI)", rows)], figures)
    ]
    if not curves.empty:
        steps, by_variant = _curves_by_variant(curves)
        sections.append(
            Section(
                "Training",
                figures=[
                    _figure(
                        "training-curves",
                        plots.training_curves(steps, by_variant, title="Training", seed=spec.seed),
                        "Mean training return (all modes) with a 95% bootstrap band",
                    )
                ],
            )
        )
    return sections


def tabular_frame(spec) -> pd.DataFrame:
    """Exact results of the paper's 3-state cMDP and ``num_random`` seeded random cMDPs."""
    rng = np.random.default_rng(spec.seed)
    cmdps = [three_state_cmdp(spec.discount)] + [
        random_cmdp(rng, spec.contexts, spec.states, spec.actions, spec.discount, f"random-{i}")
        for i in range(spec.num_random)
    ]
    rows = []
    for cmdp in cmdps:
        solution = solve(cmdp)
        for context, (best, oblivious) in enumerate(
            zip(solution.optimal_returns, solution.oblivious_returns, strict=True)
        ):
            rows.append(
                {
                    "trial": cmdp.name,
                    "test_set": "tabular",
                    "context_index": context,
                    "optimal_return": float(best),
                    "oblivious_return": float(oblivious),
                    "return": float(oblivious),
                    "oblivious_policy": str(solution.oblivious_policy),
                    "conflict_states": str(solution.conflict_states),
                }
            )
    return pd.DataFrame(rows)


def tabular_sections(spec, results: pd.DataFrame) -> list[Section]:
    rows, gaps = [], {}
    for name, group in results.groupby("trial", sort=False):
        gap = float(np.mean(group["optimal_return"] - group["oblivious_return"]))
        gaps[name] = gap
        rows.append(
            {
                "cMDP": name,
                "contexts": len(group),
                "mean optimal return": float(group["optimal_return"].mean()),
                "best oblivious return": float(group["oblivious_return"].mean()),
                "optimality gap": gap,
                "oblivious policy": group["oblivious_policy"].iloc[0],
                "conflict states": group["conflict_states"].iloc[0],
            }
        )
    text = [
        "Exact values: value iteration gives each context's optimal return; enumerating every "
        "deterministic context-oblivious policy gives the best return without the context. A gap "
        "above zero goes with a conflict state (reachable in two contexts whose optimal actions "
        f"differ there), as the paper's theorem says. Discount {spec.discount}."
    ]
    figure = _figure(
        "tabular-gaps",
        plots.bars(
            gaps,
            ylabel="optimality gap",
            title="Exact optimality gap of context-oblivious policies",
        ),
        "Exact optimality gap per cMDP",
    )
    return [Section("Tabular cMDPs", text, [("Exact solutions", rows)], [figure])]


PROTOCOL_SECTIONS: dict[str, Callable] = {
    "sensitivity": lambda spec, plan, results, curves: sensitivity_sections(spec, plan, results),
    "optimality_gap": lambda spec, plan, results, curves: optimality_gap_sections(
        spec, plan, results
    ),
    "visibility": visibility_sections,
    "train_test": train_test_sections,
}


def build_report(run: RunDir) -> str:
    """Write ``report.html`` (and figures/*.png) for a run from what is on disk; return its path."""
    spec = run.spec()
    results, curves = run.results(), run.curves()
    manifest = run.manifest()
    failures = run.failures()
    sections = [
        Section(
            "Summary",
            [
                f"Protocol {spec.protocol} on {spec.env} with agent {spec.agent}; "
                f"variants {list(spec.variants)}; {spec.seeds} seeds (base seed {spec.seed}).",
            ],
            tables=[("Progress", [_progress_row(run, spec, results, failures)])],
        )
    ]
    if spec.protocol == "tabular":
        sections += tabular_sections(spec, results) if not results.empty else []
    else:
        plan = expand(spec)
        sections.append(environment_section(spec))
        if results.empty:
            sections.append(Section("Results", ["No trial has finished yet."]))
        else:
            sections += PROTOCOL_SECTIONS[spec.protocol](spec, plan, results, curves)
    if failures:
        sections.append(
            Section(
                "Failures",
                [f"{len(failures)} chunk(s) failed; rerun with --resume to retry them."],
                tables=[
                    (
                        "Failed chunks",
                        [
                            {
                                "chunk": f["chunk"],
                                "trials": ", ".join(f["trials"]),
                                "error": f["error"],
                            }
                            for f in failures
                        ],
                    )
                ],
                code="\n\n".join(f["traceback"] for f in failures),
            )
        )
    sections.append(Section("Spec", code=yaml.safe_dump(spec_to_dict(spec), sort_keys=False)))
    timings = run.timings()
    metadata = {
        **manifest,
        "seeds": list(range(spec.seeds)),
        "base_seed": spec.seed,
        "chunk_seconds": timings,
        "total_chunk_seconds": round(sum(timings.values()), 2),
    }
    html = render(f"contextrl {spec.protocol}: {spec.name}", sections, metadata)
    figures = run.path / "figures"
    figures.mkdir(exist_ok=True)
    for section in sections:
        for figure in section.figures:
            (figures / f"{figure.name}.png").write_bytes(figure.png)
    write_text(run.path / "report.html", html)
    return str(run.path / "report.html")


def _progress_row(run: RunDir, spec, results: pd.DataFrame, failures: list) -> dict:
    if spec.protocol == "tabular":
        return {"cMDPs": results["trial"].nunique() if not results.empty else 0}
    plan = expand(spec)
    return {
        "trials": len(plan.trials),
        "trials finished": int(results["trial"].nunique()) if not results.empty else 0,
        "chunks": len(plan.chunks),
        "chunks finished": len(run.finished()),
        "chunks failed": len(failures),
        "seconds (sum over chunks)": round(sum(run.timings().values()), 1),
    }
