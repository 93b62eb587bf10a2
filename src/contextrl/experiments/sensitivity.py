"""The sensitivity protocol (paper §6.1): an agent trained on the default context, evaluated with each
feature scaled by a magnitude A × its default value."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd

from contextrl.analysis import plots
from contextrl.analysis.report import Section
from contextrl.context.features import ContextError
from contextrl.experiments.analyze import figure
from contextrl.experiments.protocols import ContextSet, Plan, grid
from contextrl.experiments.spec import (
    CommonSpec,
    SpecError,
    _as_tuple,
    _check_number,
    register_protocol,
)


@register_protocol
@dataclasses.dataclass(frozen=True)
class SensitivitySpec(CommonSpec):
    """Train on the default context; evaluate with each feature scaled by A × default (paper §6.1)."""

    protocol: str = "sensitivity"

    features: tuple[str, ...] | str = "all"  # "all": every numeric feature with a non-zero default
    magnitudes: tuple[float, ...] = tuple(round(0.1 * i, 1) for i in range(1, 23))

    def validate(self) -> None:
        super().validate()
        if not self.magnitudes:
            raise SpecError("magnitudes: give at least one magnitude A")
        for magnitude in self.magnitudes:
            _check_number("magnitudes", magnitude, 0.0)
        self.feature_names()

    vary_field = None  # --vary names the features to scale

    @classmethod
    def vary(cls, data: dict, items: list[str]) -> None:
        data["features"] = list(items)

    def expand(self) -> tuple[dict, list]:
        return _expand(self)

    def sections(self, plan, results, curves) -> list[Section]:
        return _sections(self, plan, results)

    def feature_names(self) -> tuple[str, ...]:
        space = self.space()
        if self.features == "all":
            names = tuple(
                n for n, f in space.features.items() if f.kind != "categorical" and f.default != 0
            )
        else:
            try:
                names = tuple(space.resolve(n) for n in _as_tuple(self.features))
            except ContextError as error:
                raise SpecError(f"features: {error}") from None
            for name in names:
                f = space.features[name]
                if f.kind == "categorical" or f.default == 0:
                    raise SpecError(f"features: {name} cannot be scaled (categorical or default 0)")
        if not names:
            raise SpecError("features: no feature to vary")
        return names


def _expand(spec: SensitivitySpec) -> tuple[dict, list]:
    space = spec.space()
    default = space.default()
    contexts, feature_labels, magnitudes = [], [], []
    for name in spec.feature_names():
        f = space.features[name]
        for magnitude in spec.magnitudes:
            value = magnitude * f.default
            if f.kind == "int":
                value = round(value)
            if not f.lower <= value <= f.upper:
                continue  # outside the feature's declared bounds: not a valid environment
            contexts.append(default.replace(**{name: value}))
            feature_labels.append(name)
            magnitudes.append(float(magnitude))
    sets = {
        "default": ContextSet("default", space.stack([default])),
        "scaled": ContextSet(
            "scaled", space.stack(contexts), {"feature": feature_labels, "magnitude": magnitudes}
        ),
    }
    return sets, grid(spec, "default", "default", "scaled")


def _sections(spec: SensitivitySpec, plan: Plan, results: pd.DataFrame) -> list[Section]:
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
    chart = figure(
        "sensitivity-ecdf",
        plots.sensitivity_ecdfs(returns, title=f"{spec.env}: agent trained on the default context"),
        "eCDF of test returns per feature; A is the magnitude multiplied with the default value",
    )
    text = [
        f"A {spec.agent} agent trained on the default context (hidden), evaluated with each feature "
        f"scaled by A ∈ {list(spec.magnitudes)} × default; {spec.seeds} seeds × "
        f"{spec.eval_episodes} episodes per context. Magnitudes outside a feature's bounds are skipped."
    ]
    return [Section("Sensitivity", text, [("Return per feature", rows)], [chart])]
