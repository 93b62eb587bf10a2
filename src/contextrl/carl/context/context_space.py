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


@dataclasses.dataclass(frozen=True)
class ContextFeature:
    """A named context feature with a distribution (the base of every CARL feature class)."""

    name: str

    def distribution(self) -> distributions.Distribution:
        raise NotImplementedError

    def declaration(self) -> dict[str, Any]:
        """The arguments of contextrl's ``feature(...)`` declaring this feature (default, bounds, kind)."""
        raise NotImplementedError

    def bounds(self) -> tuple[float, float]:
        lower, upper = getattr(self, "lower", None), getattr(self, "upper", None)
        if lower is None or upper is None or not math.isfinite(lower) or not math.isfinite(upper):
            raise ContextError(
                f"{self.name}: a context space needs finite lower and upper bounds, got "
                f"lower={lower!r}, upper={upper!r}; e.g. {type(self).__name__}({self.name!r}, "
                "lower=0.1, upper=10.0, ...)"
            )
        return lower, upper


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

    def distribution(self) -> distributions.Distribution:
        kind = distributions.LogUniform if self.log else distributions.Uniform
        return kind(self.lower, self.upper)

    def declaration(self) -> dict[str, Any]:
        """Without a ``default_value``, the middle of the range (geometric with ``log``), as CARL's."""
        lower, upper = self.bounds()
        default = self.default_value
        if default is None:
            default = math.sqrt(lower * upper) if self.log else (lower + upper) / 2
        return integral(self, dict(default=default, lower=lower, upper=upper))


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

    def distribution(self) -> distributions.Distribution:
        if self.log:
            raise ContextError(f"{self.name}: a log-normal context feature is not supported")
        return distributions.Normal(self.mu, self.sigma, self.lower, self.upper)

    def declaration(self) -> dict[str, Any]:
        """Without a ``default_value``, the mean ``mu``, as CARL's."""
        lower, upper = self.bounds()
        default = self.mu if self.default_value is None else self.default_value
        return integral(self, dict(default=default, lower=lower, upper=upper))


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


def integral(feature: ContextFeature, declaration: dict[str, Any]) -> dict[str, Any]:
    """An integer feature's declaration: kind int, its default rounded."""
    if isinstance(feature, INTEGRAL):
        return {**declaration, "default": round(declaration["default"]), "kind": "int"}
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

    def __init__(self, context_space: Mapping[str, ContextFeature], core: CoreSpace | None = None):
        """``core``: a registered environment's space; None declares one from ``context_space``."""
        self.context_space = dict(context_space)
        self.core = declared_space(self.context_space) if core is None else core

    @property
    def context_feature_names(self) -> list[str]:
        return list(self.context_space)

    def insert_defaults(self, context: Context, context_keys: list[str] | None = None) -> Context:
        """``context`` (validated) over the defaults, optionally only the features in ``context_keys``."""
        self.core.make(**context)
        defaults = self.get_default_context()
        if context_keys:
            defaults = {name: defaults[self.core.resolve(name)] for name in context_keys}
        return {**defaults, **context}

    def verify_context(self, context: Context) -> bool:
        """Whether every feature of ``context`` exists and its value is valid."""
        try:
            self.core.make(**context)
        except ContextError:
            return False
        return True

    def get_default_context(self) -> Context:
        return plain_values(self.core, self.core.default())

    def get_lower_and_upper_bound(self, context_feature_name: str) -> tuple[float, float]:
        return self.core.features[self.core.resolve(context_feature_name)].bounds

    def to_gymnasium_space(
        self, context_feature_names: list[str] | None = None, as_dict: bool = False
    ) -> gymnasium.spaces.Space:
        """A Box of the named features' values, or a Dict of one shape-(1,) Box per feature."""
        names = [self.core.resolve(name) for name in (context_feature_names or self.core.names)]
        low = np.array([self.core.features[n].lower for n in names], np.float32)
        high = np.array([self.core.features[n].upper for n in names], np.float32)
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
        spec = {name: self.context_space[name].distribution() for name in names}
        batch = distributions.sample(self.core, spec, size, jax.random.key(seed))
        contexts = [plain_values(self.core, batch[i]) for i in range(size)]
        return contexts[0] if size == 1 else contexts
