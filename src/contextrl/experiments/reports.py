"""Turn a run directory into a report: a summary, whether the agents learned, the protocol's own
sections (``Protocol.sections``), failures and the spec; plus the helpers protocols build sections with."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pandas as pd
import yaml

import contextrl as crl
from contextrl.analysis import plots
from contextrl.analysis.intervals import SAMPLED
from contextrl.analysis.report import Figure, Section, render
from contextrl.analysis.scores import (
    LEARNED_MARGIN,
    agent_label,
    interval_title,
    learned,
    missing_rows,
    natural_key,
    return_lines,
    score_cells,
    score_intervals,
    score_matrices,
)
from contextrl.experiments.plan import (
    TRIAL_COLUMNS,
    Outline,
    Plan,
    Trial,
    context_columns,
    expand,
    trial_columns,
)
from contextrl.experiments.protocol import protocol_of
from contextrl.experiments.runs import RunDir, write_text
from contextrl.experiments.spec import CommonSpec, spec_to_dict

AGENT_FIELDS = (
    "agent_options", "variants", "seeds", "eval_episodes", "max_steps", "batch_size", "bootstrap_reps"
)  # fmt: skip


MISSING_TEXT = (
    "Some planned results are missing (each is listed under Missing results with why); every "
    "statistic is computed on the cells that exist, and says on how many."
)


def absent_rows(
    plan: Plan | Outline,
    results: pd.DataFrame,
    contexts_of: Callable[[Trial], dict[str, Any]],
    why: Callable[[Trial], str],
) -> pd.DataFrame:
    """A row per context of every planned trial that ``results`` lacks, return NaN and ``missing``
    saying why, so a score matrix names the cell instead of dropping a seed or a context."""
    done = set(results["trial"]) if len(results) else set()
    frames = [
        pd.DataFrame({**trial_columns(t), **contexts_of(t), "return": np.nan, "missing": why(t)})
        for t in plan.trials
        if t.id not in done
    ]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def absence_reason(run: RunDir, plan: Plan | Outline) -> Callable[[Trial], str]:
    """Why a planned trial has no results: its chunk failed (with the error), has not run, or ran
    without writing its rows."""
    failed = {trial: f for f in run.failures() for trial in f["trials"]}
    finished = run.finished()
    chunk_of = {plan.trials[i].id: c for c, members in enumerate(plan.chunks) for i in members}

    def why(trial: Trial) -> str:
        chunk = chunk_of[trial.id]
        if trial.id in failed:
            return f"{trial.id}: chunk {chunk} failed: {failed[trial.id]['error']}"
        if chunk in finished:
            return f"{trial.id}: chunk {chunk} finished without its rows"
        return f"{trial.id}: chunk {chunk} has not run yet"

    return why


def run_cells(run: RunDir, plan: Plan | Outline, results: pd.DataFrame) -> pd.DataFrame:
    """The score cells of a run's results, with every planned cell that has none named (by the
    trial's test contexts: an outline does where every trial has results)."""
    names = plan.spec.space().names
    absent = absent_rows(
        plan,
        results,
        lambda trial: context_columns(plan.sets[trial.test_set], names),
        absence_reason(run, plan),
    )
    return score_cells(pd.concat([results, absent], ignore_index=True))


def figure(name: str, matplotlib_figure, caption: str) -> Figure:
    return Figure(name, plots.to_png(matplotlib_figure), caption)


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
    registered = crl.spec(spec.env)
    env = spec.make_env()
    features = env.context_space.features
    action = env.action_space
    doc = (type(env).__doc__ or "").strip().splitlines()[0]
    text = [
        f"{registered.id}, from the {registered.family} family "
        f"({'a host simulator' if spec.host else 'JAX'}): {doc}"
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


def plane_points(cells: pd.DataFrame, x_name: str, y_name: str, by: list[str]) -> pd.DataFrame:
    """Each context's mean return over seeds on the ``x_name`` × ``y_name`` plane (columns x, y,
    value): what a return heatmap draws. A context no seed has a return on has nothing to draw."""
    points = cells.groupby(by).agg(
        x=(f"ctx.{x_name}", "first"), y=(f"ctx.{y_name}", "first"), value=("return", "mean")
    )
    return points.dropna(subset=["value"])


def training_figure(spec: CommonSpec, curves: pd.DataFrame, name: str = "training-curves"):
    """Training curves with a 95 % bootstrap band over seeds, one line per agent label."""
    steps, by_label = curves_by_label(curves, agent_label)
    return figure(
        name,
        plots.training_curves(steps, by_label, title="Training return", seed=spec.seed),
        "Mean training return (episodes that ended in each update) with a 95% bootstrap band "
        "over seeds",
    )


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


def per_context_table(cells: pd.DataFrame) -> pd.DataFrame:
    """One row per agent label × evaluated context (from :func:`score_cells`): the varying features,
    mean and spread of the return over the seeds that have one, and their number; naturally sorted.
    The ``context`` key is shown where it is not the index (the optimality gap's label)."""
    features = varying_features(cells)
    frame = cells.assign(agent=agent_label(cells))
    labels = [c for c in LABEL_COLUMNS if c in frame.columns and c != "context"]
    table = (
        frame.groupby(["agent", "test_set", "context"], sort=False)
        .agg(
            context_index=("context_index", "first"),
            **{name: (f"ctx.{name}", "first") for name in features},
            **{name: (name, "first") for name in labels},
            mean_return=("return", "mean"),
            std_return=("return", "std"),
            seeds=("return", "count"),
        )
        .reset_index()
    )
    if (table["context"] == table["context_index"]).all():
        table = table.drop(columns="context")
    else:  # after the features, as a label
        table.insert(len(table.columns) - 3, "context", table.pop("context"))
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


def per_context_wide(table: pd.DataFrame) -> pd.DataFrame:
    """The per-context table (:func:`per_context_table`) with one row per evaluated context and a
    mean-return column per agent, the contexts in the table's order: easy to read across (the CSV
    has spreads and seeds). Only contexts some agent was evaluated on appear."""
    keys = [c for c in table.columns if c not in ("agent", "mean_return", "std_return", "seeds")]
    wide = table[keys].drop_duplicates().reset_index(drop=True)
    for agent in sorted(table["agent"].unique(), key=natural_key):
        mine = table.loc[table["agent"] == agent, [*keys, "mean_return"]]
        wide = wide.merge(mine.rename(columns={"mean_return": agent}), on=keys, how="left")
    return wide


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


def per_context_section(
    spec: CommonSpec,
    plan,
    cells: pd.DataFrame,
    table: pd.DataFrame,
    *,
    title: str = "Test return per context",
    prefix: str = "",
    csv: str = "results/per_context.csv",
    text: Sequence[str] = (),
    tables: Sequence[tuple[str, list[dict]]] = (),
    contexts: str | None = None,
    intervals: bool = True,
) -> Section:
    """Test return against each varied feature (CI band over seeds, training range shaded), a heat
    map when two features vary, and the per-context table (all of it in ``csv``), from the score
    cells of :func:`score_cells`; ``tables`` come last. ``contexts``: the intervals' design of the
    test contexts (default: the protocol's); ``intervals``: the agents' interval table first."""
    contexts = spec.test_contexts if contexts is None else contexts
    features = varying_features(cells)
    figures = []
    for feature in features:
        lines = return_lines(cells, f"ctx.{feature}")
        if not lines:
            continue
        figures.append(
            figure(
                f"{prefix}return-vs-{feature}",
                plots.return_vs_feature(
                    lines,
                    xlabel=feature,
                    train_range=_train_range(plan, cells, feature),
                    title=f"Test return against {feature}",
                    seed=spec.seed,
                ),
                f"Mean test return against {feature} with a 95% bootstrap band over seeds"
                + (" (averaged over the other varied features)" if len(features) > 1 else "")
                + "; grey: the training range",
            )
        )
    if len(features) == 2 and not protocol_of(spec).draws_heatmap:
        x_name, y_name = features
        low, high = float(cells["return"].min()), float(cells["return"].max())
        frame = cells.assign(agent=agent_label(cells))
        for label in sorted(frame["agent"].unique(), key=natural_key):
            points = plane_points(
                frame[frame["agent"] == label], x_name, y_name, ["test_set", "context"]
            )
            if points.empty:
                continue
            figures.append(
                figure(
                    f"{prefix}heatmap-{label.replace(', ', '-')}",
                    plots.heatmap(
                        points["x"],
                        points["y"],
                        points["value"],
                        xlabel=x_name,
                        ylabel=y_name,
                        bins=max(2, min(12, int(np.sqrt(len(points))))),
                        title=label,
                        vmin=low,
                        vmax=high,
                    ),
                    f"Mean test return over the {x_name} × {y_name} plane, {label}",
                )
            )
    wide = per_context_wide(table)
    shown = wide.head(PER_CONTEXT_ROWS).to_dict("records")
    more = len(wide) - len(shown)
    caption = "Mean return per context and agent (over seeds)" + (
        f"; first {len(shown)} of {len(wide)} contexts, all in {csv}" if more else ""
    )
    text = [*text, f"Every evaluated context, all agents: {csv}."]
    pooled = cells[cells["trials"] > 1]
    for label, group in pooled.groupby(agent_label(pooled), sort=False):
        text.append(
            f"{label}: each seed's return on a context is the mean over its "
            f"{int(group['trials'].max())} agents (trained on different contexts)."
        )
    per_context = [(caption, shown), *tables]
    if not intervals:
        return Section(title, text, per_context, figures)
    scores = score_matrices(cells)
    _, rows = score_intervals(scores, **{**spec.design, "contexts": contexts})
    return Section(
        title,
        text,
        [(interval_title("Test return", scores, contexts), rows), *per_context],
        figures,
    )


def evaluation_sections(run: RunDir, spec: CommonSpec, results: pd.DataFrame) -> list[Section]:
    """One section per ``contextrl eval`` of the run (results in evaluations/NAME.parquet); a
    trial of the run that an evaluation lacks is named there with why."""
    folder = run.path / "evaluations"
    if not folder.exists():
        return []
    plan = expand(spec)
    finished = set(results["trial"]) if len(results) else set()
    unfinished = absence_reason(run, plan)

    def why(trial: Trial) -> str:
        if trial.id in finished:
            return f"{trial.id}: finished after this evaluation; run contextrl eval again"
        return unfinished(trial) + " (so no agent to evaluate)"

    sections = []
    for file in sorted(folder.glob("*.parquet"), key=lambda p: natural_key(p.stem)):
        frame = pd.read_parquet(file)
        if frame.empty:
            continue
        tested = frame[frame["trial"] == frame["trial"].iloc[0]].drop(
            columns=[*TRIAL_COLUMNS, "return"]
        )
        columns = {c: tested[c].to_numpy() for c in tested.columns}  # every agent's contexts
        absent = absent_rows(plan, frame, lambda _, columns=columns: columns, why)
        cells = score_cells(pd.concat([frame, absent], ignore_index=True))
        table = per_context_table(cells)
        write_text(file.with_suffix(".csv"), table.to_csv(index=False))
        described = f"({frame['contexts'].iloc[0]})" if "contexts" in frame else ""
        missing = missing_rows(score_matrices(cells))
        sections.append(
            per_context_section(
                spec,
                plan,
                cells,
                table,
                title=f"Evaluation on new contexts: {file.stem}",
                prefix=f"eval-{file.stem}-",
                csv=f"evaluations/{file.stem}.csv",
                text=[
                    f"The run's saved agents evaluated without retraining on "
                    f"{frame['context_index'].nunique()} new contexts {described}".rstrip()
                    + f" ({int(frame['episodes'].iloc[0])} episodes each)."
                ]
                + ([MISSING_TEXT] if missing else []),
                tables=[("Missing results", missing)] if missing else [],
                contexts=SAMPLED,  # drawn from the distributions `contextrl eval` was given
            )
        )
    return sections


def learning_section(spec: CommonSpec, training: pd.DataFrame, plan: Plan) -> Section:
    """Per variant and agent kind: the trained agents' return on their own training contexts next to
    a random policy's on the same contexts. Kinds are never pooled (a general agent that learned
    nothing would hide behind specialists that did), and a kind trained on several sets (one
    specialist per context) is checked set by set; a warning names each kind or set that failed."""
    sets = {t.id: t.train_set for t in plan.trials}
    # a trial outside the plan's grid (hpo's best member) is its kind's only agent
    frame = training.assign(train_set=[sets.get(trial, "") for trial in training["trial"]])
    rows, warnings = [], []
    for (variant, kind), group in frame.groupby(["variant", "kind"], sort=False):
        agents = group.groupby("train_set", sort=False)[["train_return", "random_return"]].mean()
        failed = agents[~agents.apply(lambda a: learned(*a), axis=1)]
        trained, random = group["train_return"], group["random_return"]
        verdict = "yes" if failed.empty else "NO"
        if len(agents) > 1 and not failed.empty:
            verdict = f"NO for {len(failed)} of {len(agents)} training sets"
        rows.append(
            {
                "variant": variant,
                "kind": kind,
                "agents": len(group),
                "trained: mean return": float(trained.mean()),
                "trained: worst seed": float(trained.min()),
                "random policy: mean return": float(random.mean()),
                "learned": verdict,
            }
        )
        if failed.empty:
            continue
        where = ", ".join(
            (f"{kind} trained on {name}: " if len(agents) > 1 else "")
            + f"mean return {a.train_return:.4g} vs random {a.random_return:.4g}"
            for name, a in failed.iterrows()
        )
        warnings.append(
            f"{spec.agent} agents of kind {kind} ({variant}) do not clearly beat a random policy "
            f"on their own training contexts ({where}); the results below describe agents that "
            "did not learn. Train longer or tune the agent's options."
        )
    text = [
        "Each trained agent is evaluated on (up to 16 of) its own training contexts, and a uniform "
        f"random policy on the same contexts with the same keys ({spec.eval_episodes} episodes "
        f"each). Agents of one kind and variant (per training set) have learned when their mean "
        f"return is at least {LEARNED_MARGIN:.0%} of max(|random return|, 1) above the random "
        "policy's."
    ]
    return Section("Did the agents learn?", text, [("Training contexts", rows)], warnings=warnings)


def learning_check(spec: CommonSpec, training: pd.DataFrame, plan: Plan) -> Section | None:
    """The "Did the agents learn?" section, or None where nothing trained yet (or the agent does
    not learn): what the report shows and the terminal repeats (:func:`learning_verdict`)."""
    if not spec.trains_agents or training.empty or not spec.agent_entry().trained:
        return None
    return learning_section(spec, training, plan)


def learning_verdict(run: RunDir) -> list[str]:
    """The report's learned-or-warn verdict as terminal lines (none before any agent trained), so
    a run that did not learn does not end on a bare "ok"."""
    spec = run.spec()
    section = learning_check(spec, run.training(), expand(spec))
    if section is None:
        return []
    if section.warnings:
        return [f"warning: {warning}" for warning in section.warnings]
    return [
        f"{section.title} yes: every kind of agent clearly beats a random policy on its own "
        "training contexts"
    ]


def build_report(run: RunDir) -> str:
    """Write ``report.html`` (and figures/*.png) for a run from what is on disk; return its path."""
    spec = run.spec()
    protocol = protocol_of(spec)
    plan = expand(spec)
    results, curves, training = run.results(), run.curves(), run.training()
    manifest = run.manifest()
    failures = run.failures()
    summary = f"Protocol {spec.protocol}"
    if spec.trains_agents:
        summary += (
            f" on {spec.env} with agent {spec.agent}; variants {list(spec.variants)}; "
            f"{protocol.runs_text(spec)}."
        )
    sections = [
        Section(
            "Summary",
            [summary],
            tables=[("Progress", [protocol.progress_row(spec, run, plan, results, failures)])],
        )
    ]
    if spec.trains_agents:
        sections.append(environment_section(spec, changed_features(plan)))
        learning = learning_check(spec, training, plan)
        if learning is not None:
            sections.append(learning)
    if results.empty:
        sections.append(Section("Results", ["Nothing has finished yet."]))
    elif not spec.trains_agents:
        sections += protocol.sections(spec, plan, results, curves)
    else:  # every section reads the same score cells
        cells = run_cells(run, plan, results)
        extra = {"training": training} if protocol.reads_training else {}
        sections += protocol.sections(spec, plan, cells, curves, **extra)
        if protocol.training_section and not curves.empty:
            sections.append(Section("Training", figures=[training_figure(spec, curves)]))
        table = per_context_table(cells)
        write_text(run.path / "results" / "per_context.csv", table.to_csv(index=False))
        if protocol.per_context_figures:
            sections.append(
                per_context_section(
                    spec, plan, cells, table, intervals=protocol.per_context_intervals
                )
            )
        missing = missing_rows(score_matrices(cells))
        if missing:
            sections.append(
                Section("Missing results", [MISSING_TEXT], [("Missing results", missing)])
            )
    sections += evaluation_sections(run, spec, results)
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
