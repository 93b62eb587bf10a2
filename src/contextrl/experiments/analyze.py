"""Turn a run directory into a report: a summary, whether the agents learned, the protocol's own
sections (``spec.sections``), failures and the spec; plus the helpers protocols build sections with."""

from __future__ import annotations

import numpy as np
import pandas as pd
import yaml

from contextrl.analysis import metrics, plots
from contextrl.analysis.intervals import Interval
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


def environment_section(spec: CommonSpec) -> Section:
    """A radar of the run's environment next to the others of its family."""
    import contextrl as crl

    family = crl.spec(spec.env).family
    properties = {}
    for env_id in crl.registered(family):
        if crl.spec(env_id).host and env_id != spec.env:
            continue
        env = crl.spec(env_id).factory()
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
        if crl.spec(env_id).host and hasattr(env, "close"):
            env.close()
    rows = [{"environment": name, **values} for name, values in properties.items()]
    radar = figure(
        "environment-radar",
        plots.radar(properties, title=f"{family} environments"),
        "Environment properties (each axis scaled by its largest value)",
    )
    return Section("Environment", tables=[("Environment properties", rows)], figures=[radar])


def curves_by_variant(curves: pd.DataFrame) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    table = {}
    steps = np.sort(curves["step"].unique())
    for variant, group in curves.groupby("variant", sort=False):
        wide = group.pivot_table(index="trial", columns="step", values="episode_return")
        wide = wide.reindex(columns=steps).ffill(axis=1).bfill(axis=1).fillna(0.0)
        # a moving average over ~1/20 of training, so the band shows seeds, not update noise
        window = max(1, len(steps) // 20)
        table[variant] = wide.T.rolling(window, min_periods=1).mean().T.to_numpy()
    return steps, table


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
        sections.append(environment_section(spec))
        if not training.empty and spec.agent_entry().trained:
            sections.append(learning_section(spec, training))
    if results.empty:
        sections.append(Section("Results", ["Nothing has finished yet."]))
    else:
        sections += spec.sections(plan, results, curves)
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
        for item in section.figures:
            (figures / f"{item.name}.png").write_bytes(item.png)
    write_text(run.path / "report.html", html)
    return str(run.path / "report.html")
