"""A report's tables read back from its HTML, and checked value by value against the results they
came from (``results/*.parquet``, ``training/*.parquet``), each recomputed here with pandas alone.

Every table of a report is either checked or named in ``NOT_FROM_RESULTS`` with why, so a new table
fails :func:`check_report` until it has its check.
"""

from __future__ import annotations

import html.parser
import re
from pathlib import Path

import numpy as np
import pandas as pd

# Tables whose values come from declarations, not from results
NOT_FROM_RESULTS = {
    "Environment": "the environment's declared spaces and sizes",
    "Features this run changes": "the feature declarations of the features the plan sets",
}


class Report(html.parser.HTMLParser):
    """Sections of a report: title → {"text": [...], "warnings": [...], "tables": {caption: rows},
    "figures": [caption, ...]}."""

    def __init__(self, text: str):
        super().__init__()
        self.sections: dict[str, dict] = {}
        self._tag, self._buffer, self._row, self._head, self._table = None, "", [], [], None
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        self._tag, self._buffer = tag, ""
        if tag == "table":
            self._table = {"caption": "", "rows": []}
        if tag == "tr":
            self._row = []
        if tag == "p":
            self._warning = ("class", "warning") in attrs

    def handle_data(self, data):
        self._buffer += data

    def handle_endtag(self, tag):
        text = self._buffer
        if tag == "h2":
            self._section = self.sections.setdefault(
                text, {"text": [], "warnings": [], "tables": {}, "figures": []}
            )
        elif tag == "p":
            self._section["warnings" if self._warning else "text"].append(text)
        elif tag == "caption":
            self._table["caption"] = text
        elif tag == "figcaption":
            self._section["figures"].append(text)
        elif tag in ("td", "th"):
            self._row.append(text)
        elif tag == "tr":
            if self._table["rows"] or self._head:
                self._table["rows"].append(dict(zip(self._head, self._row, strict=True)))
            else:
                self._head = self._row
        elif tag == "table":
            self._section["tables"][self._table["caption"]] = self._table["rows"]
            self._head = []
        self._buffer = ""


def read_sections(path: str | Path) -> dict[str, dict]:
    return Report(Path(path).read_text(encoding="utf-8")).sections


def row(table: list[dict], **match) -> dict:
    (found,) = [r for r in table if all(r[k] == v for k, v in match.items())]
    return found


def point(interval: str) -> float:
    """The point estimate of an interval cell: "point [low, high]" or "point (no interval …)"."""
    return float(interval.split(" [")[0].split(" (")[0])


def shown(value: float) -> str:
    """A number as a report prints it."""
    return f"{value:.4g}"


def _read(folder: Path) -> pd.DataFrame:
    files = sorted(folder.glob("*.parquet"))
    return pd.concat([pd.read_parquet(f) for f in files], ignore_index=True) if files else None


def _cells(results: pd.DataFrame) -> pd.DataFrame:
    """One mean return per (agent, test set, context, seed), with the agent's label."""
    several = results["kind"].nunique() > 1
    label = results["variant"].astype(str)
    if several:
        label = results["kind"].astype(str) + ", " + label
    key = results["context"] if "context" in results else results["context_index"]
    frame = results.assign(agent=label, key=key)
    return frame.groupby(["agent", "test_set", "key", "seed"], as_index=False)["return"].mean()


def _aggregates(cells: pd.DataFrame) -> dict[str, float]:
    """Mean and median over contexts of the mean over seeds; IQM over all cells."""
    means = cells.groupby(["test_set", "key"])["return"].mean().to_numpy()
    flat = np.sort(cells["return"].to_numpy())
    cut = flat.size // 4
    return {
        "mean": float(means.mean()),
        "median": float(np.median(means)),
        "IQM": float(flat[cut : flat.size - cut].mean()),
    }


def _check_intervals(rows: list[dict], cells: pd.DataFrame, agents: dict[str, str]) -> int:
    """A "Test return" table: each agent's mean, median and IQM, and the cells they count."""
    checked = 0
    for r in rows:
        mine = cells[cells["agent"] == agents.get(r["agent"], r["agent"])]
        for name, value in _aggregates(mine).items():
            assert shown(point(r[name])) == shown(value), (r["agent"], name, r[name], value)
            checked += 1
        seeds, contexts = mine["seed"].nunique(), mine.groupby(["test_set", "key"]).ngroups
        assert r["cells (seeds × contexts)"] == (
            f"all {seeds * contexts} ({seeds} seeds × {contexts} contexts)"
        )
        checked += 1
    expected = agents if agents else set(cells["agent"])  # every agent has its row
    assert sorted(r["agent"] for r in rows) == sorted(expected)
    return checked


def _check_per_context(caption: str, rows: list[dict], results: pd.DataFrame) -> int:
    """The per-context table: one row per evaluated context, its features and each agent's mean."""
    cells = _cells(results)
    means = cells.groupby(["agent", "test_set", "key"])["return"].mean()
    contexts = results.drop_duplicates(["test_set", "context_index"])
    if "first" in caption:
        assert caption.split(" of ")[1].startswith(f"{len(contexts)} contexts"), caption
    else:
        assert len(rows) == len(contexts), (len(rows), len(contexts))
    checked = 0
    features = [c for c in results if c.startswith("ctx.") and results[c].nunique() > 1]
    for r in rows:
        index = int(r["context_index"])
        (context,) = [
            c
            for _, c in contexts.iterrows()
            if c["test_set"] == r["test_set"] and c["context_index"] == index
        ]
        for column in features:
            assert r[column.removeprefix("ctx.")] == shown(context[column])
            checked += 1
        key = context["context"] if "context" in results else index
        for agent in cells["agent"].unique():
            found = means.get((agent, r["test_set"], key), np.nan)
            assert r[agent] == shown(found), (agent, r, found)
            checked += 1
    return checked


def _check_learning(rows: list[dict], training: pd.DataFrame) -> int:
    checked = 0
    for (variant, kind), group in training.groupby(["variant", "kind"]):
        r = row(rows, variant=str(variant), kind=str(kind))
        assert r["agents"] == str(len(group))
        assert r["trained: mean return"] == shown(group["train_return"].mean())
        assert r["trained: worst seed"] == shown(group["train_return"].min())
        assert r["random policy: mean return"] == shown(group["random_return"].mean())
        checked += 4
    assert len(rows) == training.groupby(["variant", "kind"]).ngroups
    return checked


def _check_sensitivity(rows: list[dict], results: pd.DataFrame) -> int:
    cells = results.groupby(["variant", "feature", "magnitude", "seed"], as_index=False)[
        "return"
    ].mean()
    default = cells[cells["feature"] == "(default)"]
    checked = 0
    for r in rows:
        mine = pd.concat([cells[cells["feature"] == r["feature"]], default])
        mine = mine[mine["variant"] == r["variant"]]
        per_magnitude = mine.groupby("magnitude")["return"].mean()
        worst = per_magnitude.idxmin()
        assert r["return at A=1 (default context)"] == shown(per_magnitude[1.0])
        assert r["worst A"] == shown(worst)
        assert r["return at worst A"] == shown(per_magnitude[worst])
        assert r["mean over A"] == shown(per_magnitude.mean())
        checked += 4
    assert len(rows) == results.loc[results["feature"] != "(default)", "feature"].nunique() * (
        results["variant"].nunique()
    )
    return checked


def _check_gradient(rows: list[dict], results: pd.DataFrame, training: pd.DataFrame) -> int:
    """The return gradient table: per variant and feature, the trained agents' mean gradient and
    central difference, their largest gap, and the sweep's secant between the magnitudes beside 1."""
    checked = 0
    for r in rows:
        trials = training[training["variant"] == r["variant"]].dropna(
            subset=[f"gradient.{r['feature']}"]
        )
        gradient = trials[f"gradient.{r['feature']}"]
        difference = trials[f"difference.{r['feature']}"]
        assert r["seeds"] == str(len(trials))
        assert point(r["dR/dA: gradient, mean [95% CI over seeds]"]) == float(
            shown(gradient.mean())
        )
        assert r["dR/dA (central difference, mean)"] == shown(difference.mean())
        assert r["largest |gradient − difference|"] == shown((gradient - difference).abs().max())
        mine = results[
            (results["variant"] == r["variant"])
            & results["feature"].isin([r["feature"], "(default)"])
        ]
        means = mine.groupby(["magnitude", "seed"])["return"].mean().groupby("magnitude").mean()
        below, above = means.index[means.index < 1], means.index[means.index > 1]
        low, high = (below.max() if len(below) else 1.0), (above.min() if len(above) else 1.0)
        assert r["sweep slope between"] == f"A = {low:g} to {high:g}"
        assert r["sweep slope"] == shown((means[high] - means[low]) / (high - low))
        checked += 6
    return checked


def _check_regions(rows: list[dict], results: pd.DataFrame) -> int:
    checked = 0
    for r in rows:
        mine = results[
            (results["kind"] == f"mode{r['mode']}")
            & (results["variant"] == r["variant"])
            & (results["region"] == r["region"])
        ]
        per_context = mine.groupby("context_index")["return"].mean()
        assert shown(point(r["mean return"])) == shown(per_context.mean())
        checked += 1
    assert len(rows) == results.groupby(["kind", "variant", "region"]).ngroups
    return checked


def _check_best(rows: list[dict], results: pd.DataFrame) -> int:
    for r in rows:  # one PB2 run (no run column), else a row per run and hyper-parameter
        mine = results[results["seed"] == int(r.get("PB2 run", 0))]
        assert r["best"] == shown(mine[f"hp.{r['hyper-parameter']}"].iloc[0])
    assert len(rows) == results["seed"].nunique() * len({c for c in results if c.startswith("hp.")})
    assert {r["hyper-parameter"] for r in rows} == {
        c.removeprefix("hp.") for c in results if c.startswith("hp.")
    }
    return len(rows)


def _check_tabular(rows: list[dict], results: pd.DataFrame) -> int:
    checked = 0
    for name, group in results.groupby("trial"):
        r = row(rows, cMDP=str(name))
        assert r["contexts"] == str(len(group))
        assert r["mean optimal return"] == shown(group["optimal_return"].mean())
        assert r["best deterministic oblivious return"] == shown(group["oblivious_return"].mean())
        gap = (group["optimal_return"] - group["oblivious_return"]).mean()
        assert r["deterministic gap (exact)"] == shown(gap)
        checked += 4
    assert len(rows) == results["trial"].nunique()
    return checked


def _check_progress(rows: list[dict], results: pd.DataFrame) -> int:
    """The progress row: trials (cMDPs for the tabular protocol) finished; hpo's PB2 runs."""
    (progress,) = rows
    if "trials finished" in progress:
        assert progress["trials finished"] == str(results["trial"].nunique())
        assert progress["chunks failed"] == "0"
        return 2
    if "cMDPs" in progress:
        assert progress["cMDPs"] == str(results["trial"].nunique())
        return 1
    assert progress["runs finished"] == str(results["seed"].nunique())  # hpo: a seed per run
    return 1


ONE_SEED = "(no interval with one seed)"
INTERVAL = re.compile(r"\[-?[\d.]+(e[+-]?\d+)?, -?[\d.]+(e[+-]?\d+)?\]|95% (bootstrap )?CI")


def check_one_statement(title: str, section: dict) -> int:
    """A section whose interval cells all say there is no interval (one seed) shows none in its
    text or figure captions either: one statement wherever the statistic appears."""
    cells = [
        value
        for caption, rows in section["tables"].items()
        for r in rows
        for column, value in r.items()
        if column in ("mean", "median", "IQM", "mean return")
    ]
    if not cells or not all(ONE_SEED in value for value in cells):
        return 0
    for line in [*section["text"], *section["figures"]]:
        assert not INTERVAL.search(line), (
            f"{title}: the tables say {ONE_SEED}, this shows one: {line}"
        )
    return 1


def check_report(out: str | Path) -> int:
    """Assert that every table of ``out/report.html`` equals a direct computation from the run's
    results; returns how many values were checked."""
    out = Path(out)
    results, training = _read(out / "results"), _read(out / "training")
    sections = read_sections(out / "report.html")
    checked = 0
    for title, section in sections.items():
        checked += check_one_statement(title, section)
        for caption, rows in section["tables"].items():
            if caption in NOT_FROM_RESULTS:
                continue
            if caption == "Progress":
                checked += _check_progress(rows, results)
            elif caption == "Training contexts":
                checked += _check_learning(rows, training)
            elif caption == "Test return" or caption.startswith("Test return ("):
                checked += _check_intervals(rows, _cells(results), {})
            elif caption.startswith("Mean return per context and agent"):
                checked += _check_per_context(caption, rows, results)
            elif caption == "Return per feature":
                checked += _check_sensitivity(rows, results)
            elif caption == "Return gradient in A at the default context":
                checked += _check_gradient(rows, results, training)
            elif caption == "Aggregates":  # the optimality gap: the general agent, the specialists
                variant = title.removeprefix("Optimality gap (").removesuffix(")")
                agents = {"general": f"general, {variant}", "specialists": f"specialist, {variant}"}
                checked += _check_intervals(rows, _cells(results), agents)
            elif caption.startswith("Mean return per region"):
                checked += _check_regions(rows, results)
            elif caption == "Best configuration":
                checked += _check_best(rows, results)
            elif caption == "Solutions":
                checked += _check_tabular(rows, results)
            else:
                raise AssertionError(f"{title}: table {caption!r} has no check against the results")
    return checked
