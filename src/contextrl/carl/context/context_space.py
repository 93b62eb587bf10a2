"""CARL's context feature classes and ``ContextSpace``, over contextrl's feature declarations.

A CARL context feature names a feature and a distribution over it; here each one turns into the
distribution contextrl samples from (``Uniform``, ``LogUniform``, ``Normal``, ``Categorical``), checked
against the environment's declared bounds before anything is drawn. ``ContextSpace`` answers CARL's
questions (names, defaults, bounds, gymnasium space, validity) from the environment's declarations, or,
for a user's own environment, from a contextrl context type declared from the user's features.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Hashable, Mapping, Sequence
from typing import Any

import gymnasium
import jax
import numpy as np

from contextrl.carl.utils.types import Context
from contextrl.context import distributions
from contextrl.context.features import (
    ContextBase,
    ContextError,
    check_declaration,
    context_type,
    feature,
)
from contextrl.context.features import ContextSpace as CoreSpace


def checked_bounds(feature: ContextFeature, lower: Any, upper: Any) -> tuple[float, float]:
    """``lower`` and ``upper`` if they are numbers (±inf included) in order; one clear line otherwise."""
    for key, value in (("lower", lower), ("upper", upper)):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
            raise ContextError(
                f"{feature.name}: a context space needs numbers for lower and upper, got "
                f"{key}={value!r}; e.g. {type(feature).__name__}({feature.name!r}, lower=0.1, "
                "upper=10.0, ...)"
            )
        if math.isnan(value):
            raise ContextError(f"{feature.name}: {key} is NaN; give a number or ±inf")
    if lower > upper:
        raise ContextError(f"{feature.name}: lower {lower:g} is above upper {upper:g}")
    return lower, upper


@dataclasses.dataclass(frozen=True)
class ContextFeature:
    """A named context feature with a distribution (the base of every CARL feature class)."""

    name: str

    def distribution(self) -> distributions.Distribution:
        raise NotImplementedError

    def within(self, bounds: tuple[float, float]) -> distributions.Distribution:
        """The distribution to draw from for a feature bounded by ``bounds``."""
        return self.distribution()

    def declaration(self) -> dict[str, Any]:
        """The arguments of contextrl's ``feature(...)`` declaring this feature (default, bounds, kind)."""
        raise NotImplementedError

    def bounds(self) -> tuple[float, float]:
        """``lower`` and ``upper`` as declared; either may be infinite (CARL declares gravity up to inf)."""
        return checked_bounds(self, getattr(self, "lower", None), getattr(self, "upper", None))


@dataclasses.dataclass(frozen=True)
class NumericalContextFeature(ContextFeature):
    """A number feature between ``lower`` and ``upper``."""

    lower: float | None = None
    upper: float | None = None
    default_value: float | None = None
    log: bool = False
    meta: Mapping[Hashable, Any] | None = None


@dataclasses.dataclass(frozen=True)
class UniformFloatContextFeature(NumericalContextFeature):
    """Uniform (log-uniform with ``log=True``) over [lower, upper]."""

    def drawable(self) -> tuple[float, float]:
        """The bounds, refused if one is infinite: a uniform draw needs both ends."""
        lower, upper = self.bounds()
        if not (math.isfinite(lower) and math.isfinite(upper)):
            raise ContextError(
                f"{self.name}: cannot draw uniformly from [{lower:g}, {upper:g}]: a bound is "
                "infinite; give finite lower and upper to sample this feature, or leave it out of "
                "the features to sample (it keeps its default)"
            )
        return lower, upper

    def distribution(self) -> distributions.Distribution:
        kind = distributions.LogUniform if self.log else distributions.Uniform
        return kind(*self.drawable())

    def declaration(self) -> dict[str, Any]:
        """Without a ``default_value``, the middle of the range (geometric with ``log``), as CARL's."""
        default = self.default_value
        if default is None:
            lower, upper = self.bounds()
            if not (math.isfinite(lower) and math.isfinite(upper)):
                raise ContextError(
                    f"{self.name}: give a default_value; the middle of [{lower:g}, {upper:g}] "
                    "(CARL's default) is not a number"
                )
            default = math.sqrt(lower * upper) if self.log else (lower + upper) / 2
        return declared(self, default)


@dataclasses.dataclass(frozen=True)
class UniformIntegerContextFeature(UniformFloatContextFeature):
    """Uniform over the integers lower … upper."""


@dataclasses.dataclass(frozen=True)
class NormalFloatContextFeature(ContextFeature):
    """Normal(mu, sigma), truncated to [lower, upper] (default: the feature's bounds)."""

    mu: float = 0.0
    sigma: float = 1.0
    lower: float | None = None
    upper: float | None = None
    default_value: float | None = None
    log: bool = False
    meta: Mapping[Hashable, Any] | None = None

    def bounds(self) -> tuple[float, float]:
        """Without ``lower`` or ``upper`` the normal is unbounded on that side, as in CARL."""
        lower = -math.inf if self.lower is None else self.lower
        return checked_bounds(self, lower, math.inf if self.upper is None else self.upper)

    def distribution(self) -> distributions.Distribution:
        """``sigma=0`` is the point ``mu`` (CARL's tests use it for a fixed value)."""
        if self.log:
            raise ContextError(f"{self.name}: a log-normal context feature is not supported")
        if isinstance(self.sigma, (int, float, np.number)) and self.sigma == 0:
            return distributions.Constant(self.mu)
        return distributions.Normal(self.mu, self.sigma, self.lower, self.upper)

    def within(self, bounds: tuple[float, float]) -> distributions.Distribution:
        """The distribution, its truncation narrowed to the feature's ``bounds`` where it reaches past
        them (CARL accepts such a truncation): the same law as drawing and redrawing every value
        outside, said once in a warning; an empty overlap is refused."""
        distribution = self.distribution()
        lower = bounds[0] if self.lower is None else self.lower
        upper = bounds[1] if self.upper is None else self.upper
        inside = bounds[0] <= lower and upper <= bounds[1]
        if not isinstance(distribution, distributions.Normal) or inside:
            return distribution
        low, high = max(lower, bounds[0]), min(upper, bounds[1])
        if low > high:
            raise ContextError(
                f"{self.name}: the truncation [{lower:g}, {upper:g}] does not meet the "
                f"feature's bounds [{bounds[0]:g}, {bounds[1]:g}]"
            )
        warnings.warn(
            f"{self.name}: Normal truncated to [{lower:g}, {upper:g}] reaches past the "
            f"feature's bounds [{bounds[0]:g}, {bounds[1]:g}]; drawing from [{low:g}, {high:g}]",
            stacklevel=4,
        )
        return dataclasses.replace(distribution, low=low, high=high)

    def declaration(self) -> dict[str, Any]:
        """Without a ``default_value``, the mean ``mu``, as CARL's."""
        default = self.mu if self.default_value is None else self.default_value
        return declared(self, default)


@dataclasses.dataclass(frozen=True)
class NormalIntegerContextFeature(NormalFloatContextFeature):
    """Normal(mu, sigma) rounded to integers, truncated like ``NormalFloatContextFeature``."""


@dataclasses.dataclass(frozen=True)
class CategoricalContextFeature(ContextFeature):
    """One of ``choices``, optionally weighted."""

    choices: Sequence[Any] = ()
    default_value: Any = None
    meta: Mapping[Hashable, Any] | None = None
    weights: Sequence[float] | None = None

    def distribution(self) -> distributions.Distribution:
        return distributions.Categorical(tuple(self.choices), self.weights)

    def declaration(self) -> dict[str, Any]:
        """Without a ``default_value``, the most likely choice (the first when unweighted), as CARL's."""
        if not self.choices or not all(isinstance(c, str) for c in self.choices):
            raise ContextError(
                f"{self.name}: a context space needs named choices (strings), got "
                f"{list(self.choices)!r}; e.g. choices=['low', 'high']"
            )
        default = self.default_value
        if default is None:
            weights = self.weights or [1.0] * len(self.choices)
            default = self.choices[weights.index(max(weights))]
        return dict(
            default=default, lower=0, upper=0, kind="categorical", choices=tuple(self.choices)
        )


INTEGRAL = (UniformIntegerContextFeature, NormalIntegerContextFeature)


def declared(feature: ContextFeature, default: float) -> dict[str, Any]:
    """The arguments of contextrl's ``feature(...)`` for a numeric CARL feature. An infinite bound is
    declared as the widest value a context holds (float32's or int32's): every value a context can
    store lies inside it, as every finite value lies inside CARL's infinite bound."""
    lower, upper = feature.bounds()
    integer = isinstance(feature, INTEGRAL)
    widest = np.iinfo(np.int32) if integer else np.finfo(np.float32)
    declaration = dict(
        default=default,
        lower=max(lower, float(widest.min)),
        upper=min(upper, float(widest.max)),
    )
    if integer and isinstance(default, (int, float)) and math.isfinite(default):
        return {**declaration, "default": round(default), "kind": "int"}
    return declaration


def declared_space(context_space: Mapping[str, ContextFeature]) -> CoreSpace:
    """contextrl's context space of user-declared CARL features: a context type built from them, so
    validation, sampling and conversion are the core's, as for a registered environment."""
    namespace: dict[str, Any] = {"__annotations__": {}}
    for key, declared in context_space.items():
        if not isinstance(declared, ContextFeature):
            raise ContextError(
                f"{key}: expected a context feature (UniformFloatContextFeature, "
                f"NormalFloatContextFeature, ...), got {declared!r}"
            )
        if key != declared.name:
            raise ContextError(f"the key {key!r} names the feature {declared.name!r}")
        if not key.isidentifier() or hasattr(ContextBase, key):
            raise ContextError(f"{key!r} cannot name a context feature; use a Python identifier")
        namespace[key] = feature(**declared.declaration())
        try:
            check_declaration(namespace[key].metadata["feature"])
        except ValueError as error:
            raise ContextError(f"{key}: {error}") from None
        namespace["__annotations__"][key] = Any
    return context_type(type("DeclaredContext", (ContextBase,), namespace)).space


def feature_of(core: CoreSpace, name: str) -> ContextFeature:
    """The CARL feature describing a declared contextrl feature: its bounds and default."""
    declared = core.features[name]
    if declared.kind == "categorical":
        return CategoricalContextFeature(
            name, choices=declared.choices, default_value=declared.default_label()
        )
    kind = UniformIntegerContextFeature if declared.kind == "int" else UniformFloatContextFeature
    return kind(name, declared.lower, declared.upper, declared.default)


def plain_values(core: CoreSpace, context) -> Context:
    """Feature name → Python value of one contextrl context, printed as the float32 it holds."""
    values = core.to_dict(context)
    return {
        name: float(str(np.float32(value))) if core.features[name].kind == "float" else value
        for name, value in values.items()
    }


class ContextSpace:
    """The contexts of one environment, as CARL's ``ContextSpace`` shows them."""

    def __init__(
        self,
        context_space: Mapping[str, ContextFeature],
        core: CoreSpace | None = None,
        codes: Mapping[str, Mapping[Any, str]] | None = None,
    ):
        """``core``: a registered environment's space; None declares one from ``context_space``.
        ``codes``: for a categorical feature CARL writes as numbers (Brax's ``target_direction``), CARL's
        value → contextrl's choice; contexts going in and out are translated."""
        self.context_space = dict(context_space)
        self.core = declared_space(self.context_space) if core is None else core
        self.codes = {name: dict(table) for name, table in (codes or {}).items()}

    def inward(self, context: Mapping[str, Any]) -> dict[str, Any]:
        """A context with CARL's codes replaced by contextrl's choices (a choice name passes as it is)."""
        context = dict(context)
        for name, table in self.codes.items():
            value = context.get(name)
            if value is None or isinstance(value, str):
                continue
            if isinstance(value, bool) or value not in table:
                raise ContextError(f"{name}: {value!r} is not one of CARL's codes {list(table)}")
            context[name] = table[value]
        return context

    def outward(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Feature values (categorical ones by choice name) with CARL's codes where CARL has them."""
        values = dict(values)
        for name, table in self.codes.items():
            if name in values:
                values[name] = {choice: code for code, choice in table.items()}[values[name]]
        return values

    def plain(self, context) -> Context:
        """Feature name → Python value of one contextrl context, with CARL's codes where CARL has them."""
        return self.outward(plain_values(self.core, context))

    def spec_of(self, features: list[ContextFeature]) -> dict[str, Any]:
        """The distribution spec of CARL ``features`` over this space, checked (CARL's codes among a
        categorical feature's choices translated)."""
        spec = {}
        for declared in features:
            name = self.core.resolve(declared.name)
            if name in self.codes and isinstance(declared, CategoricalContextFeature):
                choices = [self.inward({name: c})[name] for c in declared.choices]
                declared = dataclasses.replace(declared, choices=choices)
            spec[name] = declared.within(self.core.features[name].bounds)
        return distributions.check_spec(self.core, spec)

    @property
    def context_feature_names(self) -> list[str]:
        return list(self.context_space)

    def insert_defaults(self, context: Context, context_keys: list[str] | None = None) -> Context:
        """``context`` (validated) over the defaults, optionally only the features in ``context_keys``."""
        self.core.make(**self.inward(context))
        defaults = self.get_default_context()
        if context_keys:
            defaults = {name: defaults[self.core.resolve(name)] for name in context_keys}
        return {**defaults, **context}

    def verify_context(self, context: Context) -> bool:
        """Whether every feature of ``context`` exists and its value is valid."""
        try:
            self.core.make(**self.inward(context))
        except ContextError:
            return False
        return True

    def get_default_context(self) -> Context:
        return self.plain(self.core.default())

    def get_lower_and_upper_bound(self, context_feature_name: str) -> tuple[float, float]:
        """The bounds as declared (an infinite one stays infinite); a categorical feature's index range."""
        name = self.core.resolve(context_feature_name)
        declared = self.context_space[name]
        if isinstance(declared, CategoricalContextFeature):
            return self.core.features[name].bounds
        return declared.bounds()

    def to_gymnasium_space(
        self, context_feature_names: list[str] | None = None, as_dict: bool = False
    ) -> gymnasium.spaces.Space:
        """A Box of the named features' values, or a Dict of one shape-(1,) Box per feature."""
        names = [self.core.resolve(name) for name in (context_feature_names or self.core.names)]
        bounds = np.array([self.get_lower_and_upper_bound(name) for name in names], np.float32)
        low, high = bounds[:, 0], bounds[:, 1]
        if not as_dict:
            return gymnasium.spaces.Box(low, high, dtype=np.float32)
        return gymnasium.spaces.Dict(
            {
                name: gymnasium.spaces.Box(low[i : i + 1], high[i : i + 1], dtype=np.float32)
                for i, name in enumerate(names)
            }
        )

    def sample_contexts(
        self, context_keys: list[str] | None = None, size: int = 1, seed: int = 0
    ) -> Context | list[Context]:
        """Contexts drawn uniformly over the bounds of ``context_keys`` (all features if None), the rest
        at their defaults; seeded. One context for ``size=1``, else a list."""
        names = [self.core.resolve(name) for name in (context_keys or self.core.names)]
        spec = self.spec_of([self.context_space[name] for name in names])
        batch = distributions.sample(self.core, spec, size, jax.random.key(seed))
        contexts = [self.plain(batch[i]) for i in range(size)]
        return contexts[0] if size == 1 else contexts
