"""Turn a run directory into a report: a summary, whether the agents learned, the protocol's own
sections (``spec.sections``), failures and the spec; plus the helpers protocols build sections with."""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pandas as pd
import yaml

from contextrl.analysis import metrics, plots
from contextrl.analysis.intervals import Interval, interval_estimates
from contextrl.analysis.report import Figure, Section, render
from contextrl.experiments.protocols import expand
from contextrl.experiments.runs import RunDir, write_text
from contextrl.experiments.spec import CommonSpec, spec_to_dict

CI_METRICS = {
    "mean": metrics.aggregate_mean,
    "median": metrics.aggregate_median,
    "IQM": metrics.aggregate_iqm,
}
# Trained agents "clearly beat" the random policy on their training contexts when their mean return
# is above the random policy's by at least this fraction of the larger of |random return| and 1.
LEARNED_MARGIN = 0.1
AGENT_FIELDS = (
    "agent_options", "variants", "seeds", "eval_episodes", "max_steps", "batch_size", "bootstrap_reps"
)  # fmt: skip


def score_matrix(frame: pd.DataFrame) -> np.ndarray:
    """Returns as (seeds × contexts) for one agent kind/variant."""
    table = frame.pivot_table(
        index="seed", columns="context_index", values="return", aggfunc="mean"
    )
    return table.dropna(axis=0).to_numpy()


def interval_rows(results: dict[str, dict[str, Interval]]) -> list[dict]:
    return [
        {"agent": name, **{metric: str(interval) for metric, interval in row.items()}}
        for name, row in results.items()
    ]


def figure(name: str, matplotlib_figure, caption: str) -> Figure:
    return Figure(name, plots.to_png(matplotlib_figure), caption)


def natural_key(text: Any) -> tuple:
    """Sort key that orders embedded numbers by value: random-2 before random-10."""
    return tuple(
        (0, int(part), "") if part.isdigit() else (1, 0, part)
        for part in re.split(r"(\d+)", str(text))
        if part
    )


def changed_features(plan) -> list[str]:
    """Features that some context of the plan sets away from its default (or varies)."""
    space = plan.spec.space()
    default = space.default()
    changed = []
    for name in space.names:
        values = [np.asarray(getattr(s.contexts, name)) for s in plan.sets.values()]
        if any(np.any(v != np.asarray(getattr(default, name))) for v in values):
            changed.append(name)
    return changed


def environment_section(spec: CommonSpec, changed: Sequence[str] = ()) -> Section:
    """The run's environment: its family, spaces and the features the run changes."""
    import contextrl as crl

    registered = crl.spec(spec.env)
    env = spec.make_env()
    features = env.context_space.features
    action = env.action_space
    doc = (type(env).__doc__ or "").strip().splitlines()[0]
    text = [
        f"{registered.id}, from the {registered.family} family "
        f"({'a host simulator' if registered.host else 'JAX'}): {doc}"
    ]
    properties = {
        "environment": registered.id,
        "family": registered.family,
        "actions": getattr(action, "n", None) or int(np.prod(action.shape)),
        "observation size": int(np.prod(env.base_observation_space.shape)),
        "time limit": env.default_max_steps if spec.max_steps is None else spec.max_steps,
        "features": len(features),
        "change dynamics": sum("dynamics" in f.affects for f in features.values()),
        "change reward": sum("reward" in f.affects for f in features.values()),
    }
    rows = [
        {
            "feature": name,
            "default": f.default_label(),
            "bounds": " | ".join(f.choices)
            if f.kind == "categorical"
            else f"[{f.lower:g}, {f.upper:g}]",
            "unit": f.unit,
            "affects": ", ".join(f.affects),
            "meaning": f.doc,
        }
        for name, f in features.items()
        if name in changed
    ]
    tables = [("Environment", [properties])]
    if rows:
        tables.append(("Features this run changes", rows))
    return Section("Environment", text, tables)


def curves_by_label(
    curves: pd.DataFrame, label: Callable[[pd.DataFrame], pd.Series]
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Training curves (trials × steps) per label (``label(curves)`` names each row's group),
    smoothed over ~1/20 of training so a band shows seeds, not update noise."""
    table = {}
    steps = np.sort(curves["step"].unique())
    for name, group in curves.groupby(label(curves), sort=False):
        wide = group.pivot_table(index="trial", columns="step", values="episode_return")
        wide = wide.reindex(columns=steps).ffill(axis=1).bfill(axis=1).fillna(0.0)
        window = max(1, len(steps) // 20)
        table[name] = wide.T.rolling(window, min_periods=1).mean().T.to_numpy()
    return steps, table


def agent_label(frame: pd.DataFrame) -> pd.Series:
    """The variant, prefixed by the trial kind when a run has several kinds (general/specialist…)."""
    if frame["kind"].nunique() > 1:
        return frame["kind"].astype(str) + ", " + frame["variant"].astype(str)
    return frame["variant"].astype(str)


def training_figure(spec: CommonSpec, curves: pd.DataFrame, name: str = "training-curves"):
    """Training curves with a 95 % bootstrap band over seeds, one line per agent label."""
    steps, by_label = curves_by_label(curves, agent_label)
    return figure(
        name,
        plots.training_curves(steps, by_label, title="Training return", seed=spec.seed),
        "Mean training return (episodes that ended in each update) with a 95% bootstrap band "
        "over seeds",
    )


def curves_by_variant(curves: pd.DataFrame) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    return curves_by_label(curves, lambda frame: frame["variant"])


PER_CONTEXT_ROWS = 30  # rows of the per-context table shown in the report (the CSV has them all)
LABEL_COLUMNS = ("region", "mode", "feature", "magnitude", "context")


def varying_features(results: pd.DataFrame) -> list[str]:
    """Numeric context features whose value differs between the evaluated contexts."""
    return [
        column[4:]
        for column in results.columns
        if column.startswith("ctx.")
        and pd.api.types.is_numeric_dtype(results[column])
        and results[column].nunique() > 1
    ]


def per_context_table(results: pd.DataFrame) -> pd.DataFrame:
    """One row per agent label × evaluated context: the varying features, mean and spread of the
    return over seeds, and the number of seeds; naturally sorted."""
    features = varying_features(results)
    frame = results.assign(agent=agent_label(results))
    labels = [c for c in LABEL_COLUMNS if c in frame.columns]
    table = (
        frame.groupby(["agent", "test_set", "context_index"], sort=False)
        .agg(
            **{name: (f"ctx.{name}", "first") for name in features},
            **{name: (name, "first") for name in labels},
            mean_return=("return", "mean"),
            std_return=("return", "std"),
            seeds=("seed", "nunique"),
        )
        .reset_index()
    )
    table["std_return"] = table["std_return"].fillna(0.0)
    order = sorted(
        range(len(table)),
        key=lambda i: (
            natural_key(table["agent"].iloc[i]),
            natural_key(table["test_set"].iloc[i]),
            *(table[name].iloc[i] for name in features),
        ),
    )
    return table.iloc[order].reset_index(drop=True)


def _binned(x: np.ndarray, bins: int = 12) -> np.ndarray:
    """Each value's bin centre: the values themselves when there are few, else equal-width bins."""
    unique = np.unique(x)
    if unique.size <= 2 * bins:
        return x
    edges = np.linspace(unique[0], unique[-1], bins + 1)
    index = np.clip(np.digitize(x, edges) - 1, 0, bins - 1)
    return ((edges[:-1] + edges[1:]) / 2)[index]


def _train_range(plan, results: pd.DataFrame, feature: str) -> tuple[float, float] | None:
    if "train_set" not in results:
        return None
    values = [
        np.asarray(getattr(plan.sets[name].contexts, feature), dtype=float)
        for name in {*results["train_set"].unique()}
        if name in plan.sets
    ]
    if not values:
        return None
    every = np.concatenate([v.ravel() for v in values])
    return float(every.min()), float(every.max())


def return_lines(
    results: pd.DataFrame, column: str, labels: pd.Series | None = None
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per label (default: the agent label): x (the value of ``column``, binned when there are many)
    and returns shaped seeds × points."""
    labels = agent_label(results) if labels is None else labels
    frame = results.assign(agent=labels, x=_binned(results[column].to_numpy(float)))
    lines = {}
    for label in sorted(frame["agent"].unique(), key=natural_key):
        group = frame[frame["agent"] == label]
        wide = group.pivot_table(index="seed", columns="x", values="return", aggfunc="mean")
        wide = wide.dropna(axis=1)
        if wide.shape[1]:
            lines[label] = (wide.columns.to_numpy(float), wide.to_numpy(float))
    return lines


def per_context_section(
    spec: CommonSpec,
    plan,
    results: pd.DataFrame,
    table: pd.DataFrame,
    *,
    title: str = "Test return per context",
    prefix: str = "",
    csv: str = "results/per_context.csv",
    text: Sequence[str] = (),
) -> Section:
    """Test return against each varied feature (CI band over seeds, training range shaded), a heat
    map when two features vary, and the per-context table (all of it in ``csv``)."""
    features = varying_features(results)
    figures = []
    for feature in features:
        lines = return_lines(results, f"ctx.{feature}")
        if not lines:
            continue
        figures.append(
            figure(
                f"{prefix}return-vs-{feature}",
                plots.return_vs_feature(
                    lines,
                    xlabel=feature,
                    train_range=_train_range(plan, results, feature),
                    title=f"Test return against {feature}",
                    seed=spec.seed,
                ),
                f"Mean test return against {feature} with a 95% bootstrap band over seeds"
                + (" (averaged over the other varied features)" if len(features) > 1 else "")
                + "; grey: the training range",
            )
        )
    if len(features) == 2 and not spec.draws_heatmap:
        x_name, y_name = features
        low, high = float(results["return"].min()), float(results["return"].max())
        frame = results.assign(agent=agent_label(results))
        for label in sorted(frame["agent"].unique(), key=natural_key):
            cells = (
                frame[frame["agent"] == label]
                .groupby(["test_set", "context_index"])
                .agg(
                    x=(f"ctx.{x_name}", "first"), y=(f"ctx.{y_name}", "first"), v=("return", "mean")
                )
            )
            figures.append(
                figure(
                    f"{prefix}heatmap-{label.replace(', ', '-')}",
                    plots.heatmap(
                        cells["x"],
                        cells["y"],
                        cells["v"],
                        xlabel=x_name,
                        ylabel=y_name,
                        bins=max(2, min(12, int(np.sqrt(len(cells))))),
                        title=label,
                        vmin=low,
                        vmax=high,
                    ),
                    f"Mean test return over the {x_name} × {y_name} plane, {label}",
                )
            )
    # one row per context, a column per agent: easy to read across; the CSV has spreads and seeds
    keys = [c for c in table.columns if c not in ("agent", "mean_return", "std_return", "seeds")]
    wide = table.pivot_table(index=keys, columns="agent", values="mean_return", sort=False)
    wide = wide[sorted(wide.columns, key=natural_key)].reset_index()
    shown = wide.head(PER_CONTEXT_ROWS).to_dict("records")
    more = len(wide) - len(shown)
    caption = "Mean return per context and agent (over seeds)" + (
        f"; first {len(shown)} of {len(wide)} contexts, all in {csv}" if more else ""
    )
    text = [*text, f"Every evaluated context, all agents: {csv}."]
    intervals = interval_estimates(
        {
            label: score_matrix(group)
            for label, group in sorted(
                results.groupby(agent_label(results), sort=False), key=lambda g: natural_key(g[0])
            )
        },
        CI_METRICS,
        reps=spec.bootstrap_reps,
        seed=spec.seed,
    )
    tables = [("Test return (95% CI over seeds and contexts)", interval_rows(intervals))]
    return Section(title, text, [*tables, (caption, shown)], figures)


def evaluation_sections(run: RunDir, spec: CommonSpec) -> list[Section]:
    """One section per ``contextrl eval`` of the run (results in evaluations/NAME.parquet)."""
    folder = run.path / "evaluations"
    if not folder.exists():
        return []
    plan = expand(spec)
    sections = []
    for file in sorted(folder.glob("*.parquet"), key=lambda p: natural_key(p.stem)):
        frame = pd.read_parquet(file)
        if frame.empty:
            continue
        table = per_context_table(frame)
        write_text(file.with_suffix(".csv"), table.to_csv(index=False))
        described = f"({frame['contexts'].iloc[0]})" if "contexts" in frame else ""
        sections.append(
            per_context_section(
                spec,
                plan,
                frame,
                table,
                title=f"Evaluation on new contexts: {file.stem}",
                prefix=f"eval-{file.stem}-",
                csv=f"evaluations/{file.stem}.csv",
                text=[
                    f"The run's saved agents evaluated without retraining on "
                    f"{frame['context_index'].nunique()} new contexts {described}".rstrip()
                    + f" ({int(frame['episodes'].iloc[0])} episodes each)."
                ],
            )
        )
    return sections


def learned(trained: float, random: float) -> bool:
    """Whether a mean trained return clearly beats the random policy's (see LEARNED_MARGIN)."""
    return trained - random >= LEARNED_MARGIN * max(abs(random), 1.0)


def learning_section(spec: CommonSpec, training: pd.DataFrame) -> Section:
    """Per variant: the trained agents' return on their training contexts next to a random policy's."""
    rows, warnings = [], []
    for variant, group in training.groupby("variant", sort=False):
        trained, random = group["train_return"], group["random_return"]
        rows.append(
            {
                "variant": variant,
                "agents": len(group),
                "trained: mean return": float(trained.mean()),
                "trained: worst seed": float(trained.min()),
                "random policy: mean return": float(random.mean()),
                "learned": "yes" if learned(trained.mean(), random.mean()) else "NO",
            }
        )
        if not learned(trained.mean(), random.mean()):
            warnings.append(
                f"{spec.agent} agents ({variant}) do not clearly beat a random policy on their own "
                f"training contexts (mean return {trained.mean():.4g} vs random "
                f"{random.mean():.4g}); the results below describe agents that did not learn. "
                "Train longer or tune the agent's options."
            )
    text = [
        "Each trained agent is evaluated on (up to 16 of) its own training contexts, and a uniform "
        f"random policy on the same contexts with the same keys ({spec.eval_episodes} episodes "
        f"each). An agent has learned when its mean return is at least {LEARNED_MARGIN:.0%} of "
        "max(|random return|, 1) above the random policy's."
    ]
    return Section("Did the agents learn?", text, [("Training contexts", rows)], warnings=warnings)


def build_report(run: RunDir) -> str:
    """Write ``report.html`` (and figures/*.png) for a run from what is on disk; return its path."""
    spec = run.spec()
    plan = expand(spec)
    results, curves, training = run.results(), run.curves(), run.training()
    manifest = run.manifest()
    failures = run.failures()
    summary = f"Protocol {spec.protocol}"
    if spec.trains_agents:
        summary += (
            f" on {spec.env} with agent {spec.agent}; variants {list(spec.variants)}; "
            f"{spec.seeds} seeds (base seed {spec.seed})."
        )
    sections = [
        Section(
            "Summary",
            [summary],
            tables=[("Progress", [spec.progress_row(run, plan, results, failures)])],
        )
    ]
    if spec.trains_agents:
        sections.append(environment_section(spec, changed_features(plan)))
        if not training.empty and spec.agent_entry().trained:
            sections.append(learning_section(spec, training))
    if results.empty:
        sections.append(Section("Results", ["Nothing has finished yet."]))
    else:
        sections += spec.sections(plan, results, curves)
        if spec.trains_agents and "context_index" in results:
            table = per_context_table(results)
            write_text(run.path / "results" / "per_context.csv", table.to_csv(index=False))
            if spec.per_context_figures:
                sections.append(per_context_section(spec, plan, results, table))
    sections += evaluation_sections(run, spec)
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
    shown = spec_to_dict(spec)
    if not spec.trains_agents:  # fields about agents mean nothing to a protocol that trains none
        for name in AGENT_FIELDS:
            shown.pop(name, None)
    sections.append(Section("Spec", code=yaml.safe_dump(shown, sort_keys=False)))
    timings = run.timings()
    metadata = {
        **manifest,
        "base_seed": spec.seed,
        "chunk_seconds": timings,
        "total_chunk_seconds": round(sum(timings.values()), 2),
    }
    if spec.trains_agents:
        metadata["seeds"] = list(range(spec.seeds))
    html = render(f"contextrl {spec.protocol}: {spec.name}", sections, metadata)
    figures = run.path / "figures"
    figures.mkdir(exist_ok=True)
    for section in sections:
        for item in section.figures:
            (figures / f"{item.name}.png").write_bytes(item.png)
    write_text(run.path / "report.html", html)
    return str(run.path / "report.html")
