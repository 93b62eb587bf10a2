"""Kirk et al.'s train/test protocol (paper §6.4): training modes A, B, C over two features and a
test grid labelled interpolation, combinatorial interpolation or extrapolation."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from contextrl.analysis import metrics, plots
from contextrl.analysis.intervals import FIXED
from contextrl.analysis.report import Section
from contextrl.analysis.scores import ONE_SEED, score_intervals, score_matrices
from contextrl.context.distributions import draw
from contextrl.experiments.plan import TRAIN_KEY, ContextSet, Plan, Trial, grid
from contextrl.experiments.protocol import Protocol, register_protocol
from contextrl.experiments.reports import figure, plane_points
from contextrl.experiments.spec import (
    CommonSpec,
    SpecError,
    check_int,
    check_number,
    feature_ranges,
    merge_features,
    parse_assignments,
)

REGIONS = ("interpolation", "combinatorial", "extrapolation (one)", "extrapolation (both)")


@dataclasses.dataclass(frozen=True)
class TrainTestSpec(CommonSpec):
    """Kirk et al.'s modes over two features (paper §6.4).

    ``train_box``/``test_box`` map each of the two features to [low, high]. Mode A trains on the whole
    train box, B on an L-shaped band of width ``band`` (a fraction of each range) along the low edges,
    C on the two low edges themselves (single values per feature). Test contexts cover the test box,
    which must reach beyond the train box on both features so every region is tested.
    """

    protocol: str = "train_test"
    variants: tuple[str, ...] = ("hidden", "concat_varying")
    modes: tuple[str, ...] = ("A", "B", "C")
    train_box: dict | None = None  # None: the environment's default (spec.ENV_DEFAULTS)
    test_box: dict | None = None
    env_defaults = ("train_box", "test_box")
    band: float = 0.1
    num_train_contexts: int = 64
    num_test_contexts: int = 144

    test_contexts = FIXED  # a grid over the test box, each point labelled with its region

    def validate(self) -> None:
        super().validate()
        for mode in self.modes:
            if mode not in ("A", "B", "C"):
                raise SpecError(f"modes: unknown mode {mode!r}; choose from ['A', 'B', 'C']")
        if not self.modes:
            raise SpecError("modes: give at least one of ['A', 'B', 'C']")
        check_int("num_train_contexts", self.num_train_contexts, 1)
        check_int("num_test_contexts", self.num_test_contexts, 4)
        side = int(np.sqrt(self.num_test_contexts))
        if side * side != self.num_test_contexts:
            raise SpecError(
                f"num_test_contexts: the test contexts form a side × side grid, and "
                f"{self.num_test_contexts} is not a square; use {side * side} or {(side + 1) ** 2}"
            )
        check_number("band", self.band, 0.0)
        if not self.band < 1.0:
            raise SpecError(f"band: must be below 1 (a fraction of the range), got {self.band!r}")
        train, test = self.boxes()
        for name in train:
            (tl, th), (sl, sh) = train[name], test[name]
            if not (sl < tl and th < sh):
                raise SpecError(
                    f"test_box/train_box: test range {[sl, sh]} of {name} overlaps the train range "
                    f"{[tl, th]} without reaching beyond it on both sides; the protocol needs "
                    "extrapolation regions"
                )

    vary_field = "train_box"  # --vary length=[0.25,0.75] tau=[0.015,0.025] (_vary)

    def boxes(self) -> tuple[dict, dict]:
        """Canonical feature names → (low, high), checked against the feature bounds."""
        space = self.space()
        out = []
        for field, box in (("train_box", self.train_box), ("test_box", self.test_box)):
            if not isinstance(box, Mapping) or len(box) != 2:
                raise SpecError(f"{field}: give exactly two features with [low, high], got {box!r}")
            resolved = feature_ranges(space, field, box)
            out.append(resolved)
        if list(out[0]) != list(out[1]):
            raise SpecError(
                f"train_box and test_box must name the same two features in the same order, "
                f"got {list(out[0])} and {list(out[1])}"
            )
        return out[0], out[1]


def region_of(
    point: Sequence[float], train_box: Sequence[tuple[float, float]], mode: str, band: float
):
    """Kirk et al.'s region of a test context relative to a training set of ``mode``."""
    inside = [low <= v <= high for v, (low, high) in zip(point, train_box, strict=True)]
    if not any(inside):
        return REGIONS[3]
    if not all(inside):
        return REGIONS[2]
    if mode == "A":
        return REGIONS[0]
    width = [band * (high - low) if mode == "B" else 0.0 for low, high in train_box]
    on_support = any(v <= low + w for v, (low, _), w in zip(point, train_box, width, strict=True))
    return REGIONS[0] if on_support else REGIONS[1]


def train_test_contexts(spec: TrainTestSpec, mode: str, key) -> Any:
    """Training contexts of one mode; every draw is direct (no rejection loop), so it always ends."""
    train_box, _ = spec.boxes()
    space = spec.space()
    (name_x, (x0, x1)), (name_y, (y0, y1)) = train_box.items()
    n = spec.num_train_contexts
    keys = jax.random.split(key, 4)
    x = jax.random.uniform(keys[0], (n,), minval=x0, maxval=x1)
    y = jax.random.uniform(keys[1], (n,), minval=y0, maxval=y1)
    if mode != "A":
        # An L-shaped set: half the contexts on the low-x edge band, half on the low-y edge band.
        fraction = spec.band if mode == "B" else 0.0
        on_x_edge = jax.random.bernoulli(keys[2], 0.5, (n,))
        thin_x = x0 + fraction * (x1 - x0) * jax.random.uniform(keys[3], (n,))
        thin_y = y0 + fraction * (y1 - y0) * jax.random.uniform(keys[3], (n,))
        x = jnp.where(on_x_edge, thin_x, x)
        y = jnp.where(on_x_edge, y, thin_y)
    defaults = draw(space, {}, n, key)
    return defaults.replace(**{name_x: np.asarray(x), name_y: np.asarray(y)})


def _test_grid(spec: TrainTestSpec) -> tuple[np.ndarray, np.ndarray]:
    """The test contexts' two features: a square grid over the test box, at most
    ``num_test_contexts`` points."""
    _, test_box = spec.boxes()
    (_, (sx0, sx1)), (_, (sy0, sy1)) = test_box.items()
    side = int(np.floor(np.sqrt(spec.num_test_contexts)))
    return np.meshgrid(np.linspace(sx0, sx1, side), np.linspace(sy0, sy1, side), indexing="ij")


def _expand(spec: TrainTestSpec) -> tuple[dict, list]:
    train_box, test_box = spec.boxes()
    space = spec.space()
    name_x, name_y = test_box
    gx, gy = _test_grid(spec)
    test = draw(space, {}, gx.size, jax.random.key(0)).replace(
        **{name_x: gx.ravel().astype(np.float32), name_y: gy.ravel().astype(np.float32)}
    )
    sets = {}
    boxes = list(train_box.values())
    for mode in spec.modes:
        key = jax.random.fold_in(jax.random.key(spec.seed), TRAIN_KEY + ord(mode))
        regions = [
            region_of((px, py), boxes, mode, spec.band)
            for px, py in zip(gx.ravel(), gy.ravel(), strict=True)
        ]
        sets[f"train-{mode}"] = ContextSet(f"train-{mode}", train_test_contexts(spec, mode, key))
        sets[f"test-{mode}"] = ContextSet(
            f"test-{mode}", test, {"region": regions, "mode": [mode] * len(regions)}
        )
    return sets, _trials(spec)


def _outline(spec: TrainTestSpec) -> tuple[dict, list]:
    tests = _test_grid(spec)[0].size
    sizes = {}
    for mode in spec.modes:
        sizes |= {f"train-{mode}": spec.num_train_contexts, f"test-{mode}": tests}
    return sizes, _trials(spec)


def _trials(spec: TrainTestSpec) -> list[Trial]:
    return [
        trial
        for mode in spec.modes
        for trial in grid(spec, f"mode{mode}", f"train-{mode}", f"test-{mode}")
    ]


def _sections(spec: TrainTestSpec, plan: Plan, cells: pd.DataFrame, curves) -> list[Section]:
    train_box, _ = spec.boxes()
    (name_x, (x0, x1)), (name_y, (y0, y1)) = train_box.items()
    figures, rows = [], []
    low, high = float(cells["return"].min()), float(cells["return"].max())
    for mode in spec.modes:
        train = plan.sets[f"train-{mode}"].contexts
        train_points = np.stack(
            [np.asarray(getattr(train, name_x)), np.asarray(getattr(train, name_y))], axis=1
        )
        for variant in spec.variants:
            group = cells[(cells["kind"] == f"mode{mode}") & (cells["variant"] == variant)]
            points = plane_points(group, name_x, name_y, ["context"])
            if points.empty:
                continue
            figures.append(
                figure(
                    f"heatmap-{mode}-{variant}",
                    plots.heatmap(
                        points["x"],
                        points["y"],
                        points["value"],
                        xlabel=name_x,
                        ylabel=name_y,
                        regions=[(x0, x1, y0, y1)],
                        train_points=train_points,
                        bins=int(np.sqrt(len(points))),
                        title=f"mode {mode}, {variant}",
                        vmin=low,
                        vmax=high,
                    ),
                    f"Mean test return over the context plane, mode {mode}, {variant}; the red box is "
                    "the training range, red dots the training contexts",
                )
            )
            for region in REGIONS:
                subset = group[group["region"] == region]
                if subset.empty:
                    continue
                scores = score_matrices(subset, subset["region"])
                _, (row,) = score_intervals(
                    scores,
                    contexts=spec.test_contexts,
                    reps=spec.bootstrap_reps,
                    seed=spec.seed,
                    metrics_={"mean": metrics.aggregate_mean},
                )
                rows.append(
                    {
                        "mode": mode,
                        "variant": variant,
                        "region": region,
                        "mean return": row["mean"],
                        "cells (seeds × contexts)": row["cells (seeds × contexts)"],
                    }
                )
    over = "95% CI over seeds, each with all its contexts" if spec.seeds > 1 else ONE_SEED
    text = [
        f"Kirk et al.'s evaluation protocol over {name_x} × {name_y}: mode A trains on the whole box, "
        f"B on an L-shaped band ({spec.band:.0%} of each range) along its low edges, C on the two "
        "low edges only. Test contexts form a grid over the test box; each is labelled interpolation, "
        "combinatorial interpolation (inside the box, off the training support) or extrapolation in "
        "one or both features."
    ]
    return [
        Section(
            "Train/test modes",
            text,
            [(f"Mean return per region ({over})", rows)],
            figures,
        )
    ]


def _vary(data: dict, items: list[str]) -> str | None:
    """``--vary FEATURE=[LOW,HIGH]`` sets a feature's training range, on top of a config's."""
    boxes = parse_assignments(items, "--vary", "FEATURE=[LOW,HIGH]")
    return merge_features(data, "train_box", boxes)


register_protocol(
    Protocol(
        TrainTestSpec,
        _sections,
        _expand,
        _outline,
        vary=_vary,
        draws_heatmap=True,  # its sections draw a heat map per mode and variant
    )
)
