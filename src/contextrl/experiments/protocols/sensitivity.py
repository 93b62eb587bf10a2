"""The sensitivity protocol (paper §6.1): an agent trained on the default context, evaluated with each
feature scaled by a magnitude A × its default value."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from contextrl.analysis import metrics, plots
from contextrl.analysis.intervals import FIXED, bootstrap_ci
from contextrl.analysis.report import Section
from contextrl.analysis.scores import DEFAULT_LABEL, magnitude_lines, natural_key
from contextrl.context.features import ContextError
from contextrl.experiments.plan import ContextSet, Plan, grid
from contextrl.experiments.protocol import Protocol, register_protocol
from contextrl.experiments.reports import figure
from contextrl.experiments.spec import (
    CommonSpec,
    SpecError,
    check_number,
    names_tuple,
)
from contextrl.experiments.trials import GRADIENT_STEP


@dataclasses.dataclass(frozen=True)
class SensitivitySpec(CommonSpec):
    """Train on the default context; evaluate with each feature scaled by A × default (paper §6.1)."""

    protocol: str = "sensitivity"

    features: tuple[str, ...] | str = "all"  # "all": every numeric feature with a non-zero default
    magnitudes: tuple[float, ...] = tuple(round(0.1 * i, 1) for i in range(1, 23))
    # beside the sweep: each agent's return gradient in A at the default context, where the
    # environment's dynamics are differentiable (``contextrl.core.gradient``)
    gradient: bool = True

    test_contexts = FIXED  # the sweep of magnitudes is the claim's own set
    vary_field = None  # --vary names the features to scale (_vary)

    def validate(self) -> None:
        super().validate()
        if not self.magnitudes:
            raise SpecError("magnitudes: give at least one magnitude A")
        for magnitude in self.magnitudes:
            check_number("magnitudes", magnitude, 0.0)
        self.scaled_values()  # refuses magnitudes that would be dropped

    def scaled_values(self) -> tuple[list[tuple[str, float, float]], list[str]]:
        """(feature, A, value) for every A ≠ 1 inside the feature's bounds, and notes of the pairs left
        out. A magnitude that no feature can take is refused, and so is any that a feature named in
        ``features`` cannot take: a value the user asked for is never dropped silently."""
        space = self.space()
        explicit = self.features != "all"
        kept, skipped, usable = [], [], set()
        for name in self.feature_names():
            f = space.features[name]
            for magnitude in self.magnitudes:
                value = magnitude * f.default
                if f.kind == "int":
                    value = round(value)
                if not f.lower <= value <= f.upper:
                    if explicit:
                        raise SpecError(
                            f"magnitudes: A={magnitude:g} gives {name} = {value:g}, outside its "
                            f"bounds [{f.lower:g}, {f.upper:g}]; remove it or choose A in "
                            f"[{f.lower / f.default:.3g}, {f.upper / f.default:.3g}]"
                        )
                    skipped.append(f"{name} at A={magnitude:g}")
                    continue
                usable.add(magnitude)
                if magnitude != 1.0:
                    kept.append((name, float(magnitude), value))
        unused = [m for m in self.magnitudes if m not in usable]
        if unused:
            raise SpecError(
                f"magnitudes: {unused} put every feature outside its bounds; nothing would be "
                "evaluated there"
            )
        return kept, skipped

    def gradient_features(self, env) -> tuple[str, ...]:
        if not (self.gradient and getattr(env, "differentiable", False)):
            return ()
        space = env.context_space
        return tuple(n for n in self.feature_names() if space.features[n].kind == "float")

    def feature_names(self) -> tuple[str, ...]:
        space = self.space()
        if self.features == "all":
            names = tuple(
                n for n, f in space.features.items() if f.kind != "categorical" and f.default != 0
            )
        else:
            try:
                names = tuple(space.resolve(n) for n in names_tuple(self.features))
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
    kept, _ = spec.scaled_values()
    # one evaluation of the default context (A = 1 for every feature), then each feature scaled
    contexts = [default] + [default.replace(**{name: value}) for name, _, value in kept]
    sets = {
        "default": ContextSet("default", space.stack([default])),
        "scaled": ContextSet(
            "scaled",
            space.stack(contexts),
            {
                "feature": [DEFAULT_LABEL] + [name for name, _, _ in kept],
                "magnitude": [1.0] + [magnitude for _, magnitude, _ in kept],
            },
        ),
    }
    return sets, grid(spec, "default", "default", "scaled")


def _outline(spec: SensitivitySpec) -> tuple[dict, list]:
    """The default context, and it followed by each feature scaled (``_expand``'s sets)."""
    kept, _ = spec.scaled_values()
    return {"default": 1, "scaled": 1 + len(kept)}, grid(spec, "default", "default", "scaled")


def _sweep_slope(cells: pd.DataFrame, feature: str, variant: str) -> tuple[str, float]:
    """The sweep's own slope at A = 1: the mean return's change between the magnitudes nearest 1 on
    either side (the default context where a side has none), over the seeds' mean returns."""
    rows = cells[(cells["variant"] == variant) & (cells["feature"].isin([feature, DEFAULT_LABEL]))]
    means = rows.groupby("magnitude")["return"].mean()
    below = [m for m in means.index if m < 1.0] or [1.0]
    above = [m for m in means.index if m > 1.0] or [1.0]
    low, high = max(below), min(above)
    if low == high:
        return "", np.nan
    return f"A = {low:g} to {high:g}", float((means[high] - means[low]) / (high - low))


def _gradient_section(spec: SensitivitySpec, cells: pd.DataFrame, training) -> Section | None:
    """Each agent's return gradient in A at the default context beside its central difference and
    the sweep's slope there: one differentiated pass against the sweep's grid of rollouts."""
    columns = [c for c in training.columns if c.startswith("gradient.")]
    if not columns:
        return None
    rows = []
    for variant, trials in training.groupby("variant", sort=False):
        for column in columns:
            feature = column.removeprefix("gradient.")
            gradient = trials[column].to_numpy(float)
            kept = np.isfinite(gradient)  # trained agents only
            if not kept.any():
                continue
            gradient = gradient[kept]
            difference = trials[f"difference.{feature}"].to_numpy(float)[kept]
            interval = bootstrap_ci(
                gradient[:, None],
                metrics.aggregate_mean,
                reps=spec.bootstrap_reps,
                seed=spec.seed,
            )
            where, slope = _sweep_slope(cells, feature, variant)
            rows.append(
                {
                    "feature": feature,
                    "variant": variant,
                    "seeds": len(gradient),
                    "dR/dA: gradient, mean [95% CI over seeds]": str(interval),
                    "dR/dA (central difference, mean)": float(np.nanmean(difference)),
                    "largest |gradient − difference|": float(
                        np.nanmax(np.abs(gradient - difference))
                    ),
                    "sweep slope": slope,
                    "sweep slope between": where,
                }
            )
    magnitudes = len([m for m in spec.magnitudes if m != 1.0])
    text = [
        "The derivative of each agent's mean return over "
        f"{spec.eval_episodes} episodes with respect to each feature's magnitude A at the default "
        "context (A = 1), from one differentiated rollout per episode "
        "(contextrl.core.gradient: the agent's deterministic policy, the episodes' draws held fixed, "
        "the terminating step counted by its part before the threshold), against the sweep's "
        f"{magnitudes} magnitudes × {spec.eval_episodes} episodes of rollouts per feature. "
        f"The central difference at A = 1 ± {GRADIENT_STEP:g} over the same episodes and draws "
        "checks the derivative; the sweep's slope between its magnitudes nearest 1 is a secant "
        "over other draws, so it differs where the return is not smooth in A (an action that "
        "switches, an episode that ends at another step)."
    ]
    return Section("Return gradient", text, [("Return gradient in A at the default context", rows)])


def _sections(
    spec: SensitivitySpec, plan: Plan, cells: pd.DataFrame, curves, training=None
) -> list[Section]:
    by_feature = magnitude_lines(cells)
    rows = []
    for feature, lines in by_feature.items():
        for variant, (x, runs) in lines.items():
            # every magnitude in x has a return (return_lines leaves out points without one)
            means = dict(zip(x, np.ma.getdata(metrics.context_means(runs)), strict=True))
            worst = min(means, key=means.get)
            rows.append(
                {
                    "feature": feature,
                    "variant": variant,
                    "return at A=1 (default context)": means.get(1.0, np.nan),
                    "worst A": worst,
                    "return at worst A": means[worst],
                    "mean over A": metrics.aggregate_mean(runs),
                }
            )
    figures = [
        figure(
            f"sensitivity-{feature}",
            plots.return_vs_feature(
                lines,
                xlabel=f"A (× default {feature})",
                train_range=(1.0, 1.0),
                title=f"{spec.env}: {feature}",
                seed=spec.seed,
            ),
            f"Mean test return against the magnitude A of {feature} with a 95% band over seeds; "
            "the grey line is the training context (A = 1, shared by every feature)",
        )
        for feature, lines in by_feature.items()
    ]
    # the default context is A = 1 of every feature: each panel runs from the smallest A to the largest
    default = cells.loc[cells["feature"] == DEFAULT_LABEL, "return"].dropna().to_numpy()
    returns = {
        feature: {
            1.0: default,
            **{m: group["return"].dropna().to_numpy() for m, group in rows.groupby("magnitude")},
        }
        for feature, rows in cells.groupby("feature", sort=False)
        if feature != DEFAULT_LABEL
    }
    figures.append(
        figure(
            "sensitivity-ecdf",
            plots.sensitivity_ecdfs(returns),
            "eCDF of test returns per feature and magnitude A (A = 1: the default context)"
            + ("; with one seed a line is one return, a single step" if spec.seeds == 1 else ""),
        )
    )
    _, skipped = spec.scaled_values()
    ran = sorted(cells.loc[cells["return"].notna(), "variant"].unique(), key=natural_key)
    text = [
        f"{spec.agent} agents trained on the default context, with context visibility "
        f"{', '.join(ran)}, each evaluated once on the default context and with each feature "
        f"scaled by A ∈ {list(spec.magnitudes)} × default; {spec.seeds} seeds × "
        f"{spec.eval_episodes} episodes per context. A table row per feature and variant."
    ]
    if skipped:
        text.append(f"Outside the feature bounds, so not evaluated: {', '.join(skipped)}.")
    sections = [Section("Sensitivity", text, [("Return per feature", rows)], figures)]
    gradient = (
        None if training is None or training.empty else _gradient_section(spec, cells, training)
    )
    return sections + ([gradient] if gradient is not None else [])


def _vary(data: dict, items: list[str]) -> str | None:
    """``--vary g --vary l`` names the features to scale, added to those a config names; a
    distribution (``l=uniform:…``, other protocols' syntax) is refused with the syntax to use."""
    for item in items:
        if "=" in item:
            raise SpecError(
                f"--vary: sensitivity takes feature names (it scales each by the magnitudes), "
                f"got {item!r}; e.g. --vary {item.partition('=')[0].strip()} and "
                "--set 'magnitudes=[0.5, 1, 2]'"
            )
    existing = data.get("features")
    if not isinstance(existing, (list, tuple)) or not existing:
        data["features"] = list(items)  # replaces "all"
        return None
    data["features"] = list(dict.fromkeys([*existing, *items]))
    kept = [name for name in existing if name not in items]
    return (
        f"--vary: features keeps {kept} from the config; now {data['features']}" if kept else None
    )


register_protocol(
    Protocol(
        SensitivitySpec,
        _sections,
        _expand,
        _outline,
        vary=_vary,
        per_context_figures=False,  # its own view: return against the magnitude A per feature
        reads_training=True,  # the agents' return gradients come with their training returns
    )
)
