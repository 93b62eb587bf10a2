"""The figures of a contextual-RL study: eCDFs, training curves with CI bands, histograms,
2-D heat maps with the training region outlined, interval plots and an environment-property radar.

Every function returns a matplotlib Figure (Agg backend, no display needed); :func:`to_png` turns one
into bytes for the HTML report. matplotlib is imported with the first figure: it takes about a second,
which a command that draws nothing (a dry run, ``list``) does not pay.
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from contextrl.analysis.intervals import Interval, curve_band

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def _matplotlib() -> Any:
    """The matplotlib module, with the parts the figures use (colour maps, patches) loaded."""
    import matplotlib
    import matplotlib.patches  # noqa: F401  (loads matplotlib.patches as an attribute)

    return matplotlib


def _figure(figsize=None, layout=None) -> Figure:
    """A new Figure drawing to memory, outside pyplot (no backend chosen, whatever the process uses)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=figsize, layout=layout)
    FigureCanvasAgg(figure)
    return figure


def to_png(figure: Figure, dpi: int = 100) -> bytes:
    """The figure as PNG bytes; the figure is closed afterwards."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
    return buffer.getvalue()


def _subplots(rows: int = 1, columns: int = 1, figsize=None, layout=None, **kwargs):
    """A new Figure and its axes, like ``pyplot.subplots`` but outside pyplot (no backend chosen)."""
    figure = _figure(figsize, layout)
    return figure, figure.subplots(rows, columns, **kwargs)


def ecdf_values(values) -> tuple[np.ndarray, np.ndarray]:
    """Sorted values and the fraction of values at or below each."""
    x = np.sort(np.asarray(values, dtype=float).ravel())
    return x, np.arange(1, x.size + 1) / x.size


def _ecdf_line(axis, values, **style) -> None:
    """An eCDF drawn from 0 at its smallest value, so one value is a visible step, not a point."""
    x, y = ecdf_values(values)
    axis.step(np.r_[x[:1], x], np.r_[0.0, y], where="post", **style)


def ecdf(returns_by_label: Mapping[str, Sequence[float]], title: str = "", xlabel: str = "return"):
    """One eCDF line per label (further right is better)."""
    figure, axis = _subplots(figsize=(5, 3.5))
    for label, values in returns_by_label.items():
        _ecdf_line(axis, values, label=str(label))
    axis.set(xlabel=xlabel, ylabel="proportion", title=title, ylim=(0, 1.02))
    axis.legend(fontsize="small")
    axis.grid(alpha=0.3)
    return figure


def sensitivity_ecdfs(returns: Mapping[str, Mapping[float, Sequence[float]]], title: str = ""):
    """A panel per feature, one eCDF per magnitude A coloured from low to high (the paper's Fig. 3)."""
    features = list(returns)
    columns = min(3, len(features))
    rows = -(-len(features) // columns)
    # constrained layout keeps the figure title, panel titles and colour bar from overlapping
    figure, axes = _subplots(
        rows,
        columns,
        figsize=(4.2 * columns, 3.2 * rows),
        squeeze=False,
        sharey=True,
        layout="constrained",
    )
    matplotlib = _matplotlib()
    cmap = matplotlib.colormaps["viridis"]
    # one scale for every panel and the colour bar: from the smallest magnitude to the largest
    every = [magnitude for by_magnitude in returns.values() for magnitude in by_magnitude]
    norm = matplotlib.colors.Normalize(min(every), max(every))
    if norm.vmin == norm.vmax:
        norm = matplotlib.colors.Normalize(norm.vmin - 0.5, norm.vmax + 0.5)
    for axis, name in zip(axes.ravel(), features, strict=False):
        for magnitude in sorted(returns[name]):
            style = {"color": cmap(norm(magnitude)), "label": f"A={magnitude:g}"}
            _ecdf_line(axis, returns[name][magnitude], **style)
        axis.set(title=name, xlabel="return", ylim=(0, 1.02))
        axis.grid(alpha=0.3)
    for axis in axes.ravel()[len(features) :]:
        axis.axis("off")
    axes[0, 0].set_ylabel("proportion")
    mappable = matplotlib.cm.ScalarMappable(cmap=cmap, norm=norm)
    figure.colorbar(mappable, ax=axes, label="magnitude A (× default)", shrink=0.8)
    if title:
        figure.suptitle(title)
    return figure


def training_curves(
    steps: Sequence[float] | Mapping[str, Sequence[float]],
    curves_by_label: Mapping[str, np.ndarray],
    title: str = "",
    seed: int = 0,
):
    """Mean training curve per label with a 95 % bootstrap band over runs (runs × points).

    ``steps`` is shared, or a mapping label → steps for curves logged at different steps."""
    figure, axis = _subplots(figsize=(5.5, 3.5))
    for label, curves in curves_by_label.items():
        x = steps[label] if isinstance(steps, Mapping) else steps
        mean, low, high = curve_band(curves, seed=seed)
        (line,) = axis.plot(x, mean, label=str(label))
        axis.fill_between(x, low, high, color=line.get_color(), alpha=0.25)
    axis.set(xlabel="environment steps", ylabel="episode return", title=title)
    axis.legend(fontsize="small")
    axis.grid(alpha=0.3)
    return figure


def histograms(returns_by_label: Mapping[str, Sequence[float]], title: str = "", bins: int = 20):
    """Overlaid histograms of test returns."""
    figure, axis = _subplots(figsize=(5, 3.5))
    every = np.concatenate([np.ravel(v) for v in returns_by_label.values()])
    edges = np.histogram_bin_edges(every, bins=bins)
    for label, values in returns_by_label.items():
        axis.hist(np.ravel(values), bins=edges, alpha=0.5, label=str(label))
    axis.set(xlabel="return", ylabel="count", title=title)
    axis.legend(fontsize="small")
    return figure


def intervals(results: Mapping[str, Mapping[str, Interval]], title: str = ""):
    """rliable-style interval plot: a panel per metric, a bar (CI) and tick (point) per label."""
    labels = list(results)
    metrics = list(next(iter(results.values())))
    figure, axes = _subplots(
        1,
        len(metrics),
        figsize=(3.2 * len(metrics), 1.0 + 0.5 * len(labels)),
        squeeze=False,
        layout="constrained",
    )
    for axis, metric in zip(axes[0], metrics, strict=True):
        for row, label in enumerate(labels):
            interval = results[label][metric]
            if interval.high > interval.low:  # a point alone (no interval) has no bar
                width = interval.high - interval.low
                axis.barh(row, width, left=interval.low, height=0.6, alpha=0.6)
            axis.vlines(interval.point, row - 0.3, row + 0.3, color="black")
        axis.set_yticks(range(len(labels)), labels if axis is axes[0, 0] else [""] * len(labels))
        axis.set_title(metric)
        axis.grid(axis="x", alpha=0.3)
    if title:
        figure.suptitle(title)
    return figure


def heatmap(
    x,
    y,
    values,
    *,
    xlabel: str,
    ylabel: str,
    regions: Sequence[tuple[float, float, float, float]] = (),
    train_points=None,
    bins: int = 12,
    title: str = "",
    vmin: float | None = None,
    vmax: float | None = None,
):
    """Mean value per cell of the 2-D context plane; training boxes (x0, x1, y0, y1) outlined in red.

    ``vmin``/``vmax`` fix the colour scale (to share it between panels); by default it spans the
    values, whatever their sign. Equal limits are widened by ½ so a constant plane still has a scale.
    """
    x, y, values = (np.asarray(a, dtype=float).ravel() for a in (x, y, values))
    vmin = float(np.nanmin(values)) if vmin is None else float(vmin)
    vmax = float(np.nanmax(values)) if vmax is None else float(vmax)
    if not vmin <= vmax:
        raise ValueError(f"heatmap: vmin ({vmin:g}) must not exceed vmax ({vmax:g})")
    if vmin == vmax:
        vmin, vmax = vmin - 0.5, vmax + 0.5
    xedges = np.linspace(x.min(), x.max(), bins + 1)
    yedges = np.linspace(y.min(), y.max(), bins + 1)
    total, _, _ = np.histogram2d(x, y, bins=(xedges, yedges), weights=values)
    count, _, _ = np.histogram2d(x, y, bins=(xedges, yedges))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / count, np.nan)
    figure, axis = _subplots(figsize=(5, 4))
    mesh = axis.pcolormesh(xedges, yedges, mean.T, cmap="viridis", vmin=vmin, vmax=vmax)
    figure.colorbar(mesh, ax=axis, label="mean return")
    for x0, x1, y0, y1 in regions:
        axis.add_patch(
            _matplotlib().patches.Rectangle(
                (x0, y0), max(x1 - x0, 1e-9), max(y1 - y0, 1e-9), fill=False, color="red", lw=2
            )
        )
    if train_points is not None:
        points = np.asarray(train_points, dtype=float)
        axis.scatter(points[:, 0], points[:, 1], s=6, color="red", alpha=0.5, label="train")
        axis.legend(fontsize="small", loc="upper right")
    axis.set(xlabel=xlabel, ylabel=ylabel, title=title)
    return figure


def schedules(
    panels: Mapping[str, Mapping[str, tuple[Sequence[float], Sequence[float]]]], xlabel: str = ""
):
    """A panel per quantity (a hyper-parameter, the return), one step line per member over time."""
    names = list(panels)
    columns = min(3, len(names))
    rows = -(-len(names) // columns)
    figure, axes = _subplots(rows, columns, figsize=(4.2 * columns, 3.0 * rows), squeeze=False)
    for axis, name in zip(axes.ravel(), names, strict=False):
        for label, (x, y) in panels[name].items():
            axis.step(np.asarray(x), np.asarray(y), where="post", label=str(label), alpha=0.8)
        axis.set(xlabel=xlabel, title=name)
        axis.grid(alpha=0.3)
    for axis in axes.ravel()[len(names) :]:
        axis.set_visible(False)
    axes.ravel()[0].legend(fontsize="x-small")
    figure.tight_layout()
    return figure


def radar(properties: Mapping[str, Mapping[str, float]], title: str = ""):
    """Environment properties on a radar chart, each axis scaled by its largest value."""
    names = list(properties)
    axes_names = list(next(iter(properties.values())))
    top = {a: max(float(properties[n][a]) for n in names) or 1.0 for a in axes_names}
    angles = np.linspace(0, 2 * np.pi, len(axes_names), endpoint=False)
    closed = np.append(angles, angles[0])
    figure = _figure(figsize=(5, 5))
    axis = figure.add_subplot(projection="polar")
    for name in names:
        values = [float(properties[name][a]) / top[a] for a in axes_names]
        axis.plot(closed, values + values[:1], label=name)
        axis.fill(closed, values + values[:1], alpha=0.15)
    axis.set_xticks(angles, [f"{a}\n(max {top[a]:g})" for a in axes_names], fontsize="small")
    axis.set_yticklabels([])
    axis.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.1, 1.0))
    if title:
        axis.set_title(title, pad=24)
    return figure


def bars(values: Mapping[str, float], *, ylabel: str, title: str = ""):
    """One bar per label (e.g. the exact optimality gap of each tabular cMDP)."""
    figure, axis = _subplots(figsize=(max(4, 0.7 * len(values)), 3.5))
    axis.bar(range(len(values)), list(values.values()), color="tab:blue")
    axis.set_xticks(range(len(values)), list(values), rotation=45, ha="right", fontsize="small")
    axis.set(ylabel=ylabel, title=title)
    axis.grid(axis="y", alpha=0.3)
    return figure


def scatter(
    x, y_by_label: Mapping[str, Sequence[float]], *, xlabel: str, ylabel: str, title: str = ""
):
    """Points per label against one feature (e.g. the per-context gap against pole length)."""
    figure, axis = _subplots(figsize=(5, 3.5))
    for label, y in y_by_label.items():
        axis.scatter(x, y, s=12, label=str(label))
    axis.axhline(0.0, color="gray", lw=0.8)
    axis.set(xlabel=xlabel, ylabel=ylabel, title=title)
    axis.legend(fontsize="small")
    axis.grid(alpha=0.3)
    return figure


def return_vs_feature(
    lines: Mapping[str, tuple[Sequence[float], np.ndarray]],
    *,
    xlabel: str,
    train_range: tuple[float, float] | None = None,
    ylabel: str = "test return",
    title: str = "",
    seed: int = 0,
    reference: float | None = None,
):
    """Mean return against one context feature per label, with a 95 % bootstrap band over runs.

    ``lines`` maps a label to (x values, returns shaped runs × points); ``train_range`` (low, high) is
    shaded as the training range (a line when low == high); ``reference`` draws a dashed horizontal
    line (e.g. the return at the default context).
    """
    figure, axis = _subplots(figsize=(5.5, 3.6))
    if train_range is not None:
        low, high = train_range
        if high > low:
            axis.axvspan(low, high, color="gray", alpha=0.15, label="training range")
        else:
            axis.axvline(low, color="gray", lw=1.5, alpha=0.6, label="training value")
    for label, (x, runs) in lines.items():
        mean, low, high = curve_band(runs, seed=seed)
        (line,) = axis.plot(x, mean, marker="o", ms=3, label=str(label))
        axis.fill_between(x, low, high, color=line.get_color(), alpha=0.2)
    if reference is not None:
        axis.axhline(reference, color="black", ls="--", lw=0.8, label="default context")
    axis.set(xlabel=xlabel, ylabel=ylabel, title=title)
    axis.legend(fontsize="small")
    axis.grid(alpha=0.3)
    return figure
