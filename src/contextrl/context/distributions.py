"""Distributions over one context feature, and seeded batched sampling of whole contexts.

A distribution is a small frozen dataclass with ``sample(key, n, feature)``. It is checked against the
feature's bounds before anything is drawn: a distribution that can reach outside them is refused, so a
sampled context is always valid (CARL's samplers yield inf/nan for unbounded features).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import ContextError, ContextSpace, Feature


def _finite(feature: Feature, name: str, **values: float) -> None:
    for key, value in values.items():
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
            raise ContextError(f"{feature.name}: {name}: {key} must be a number, got {value!r}")
        if not math.isfinite(value):
            raise ContextError(f"{feature.name}: {name}: {key} must be finite, got {value!r}")


def _inside(feature: Feature, low: float, high: float, what: str) -> None:
    if low < feature.lower or high > feature.upper:
        raise ContextError(
            f"{feature.name}: {what} reaches [{low:g}, {high:g}], outside the feature's bounds "
            f"[{feature.lower:g}, {feature.upper:g}]"
        )


def _numeric_only(feature: Feature, what: str) -> None:
    if feature.kind == "categorical":
        raise ContextError(
            f"{feature.name} is categorical; use Categorical or Constant instead of {what}"
        )


@dataclasses.dataclass(frozen=True)
class Uniform:
    """Uniform over [low, high]; integers drawn uniformly from low..high inclusive."""

    low: float
    high: float

    def check(self, feature: Feature) -> None:
        _finite(feature, "Uniform", low=self.low, high=self.high)
        _numeric_only(feature, "Uniform")
        if self.low > self.high:
            raise ContextError(
                f"{feature.name}: Uniform is empty (low {self.low:g} > high {self.high:g})"
            )
        _inside(feature, self.low, self.high, "Uniform")

    def sample(self, key, n: int, feature: Feature) -> jax.Array:
        if feature.kind == "int":
            low, high = jnp.ceil(self.low), jnp.floor(self.high) + 1
            return jax.random.randint(key, (n,), low.astype(jnp.int32), high.astype(jnp.int32))
        return jax.random.uniform(key, (n,), minval=self.low, maxval=self.high)


@dataclasses.dataclass(frozen=True)
class LogUniform:
    """Log-uniform over [low, high], both positive (scales spread evenly per decade)."""

    low: float
    high: float

    def check(self, feature: Feature) -> None:
        _finite(feature, "LogUniform", low=self.low, high=self.high)
        _numeric_only(feature, "LogUniform")
        if not 0 < self.low <= self.high:
            raise ContextError(
                f"{feature.name}: LogUniform needs 0 < low <= high, got [{self.low:g}, {self.high:g}]"
            )
        _inside(feature, self.low, self.high, "LogUniform")

    def sample(self, key, n: int, feature: Feature) -> jax.Array:
        u = jax.random.uniform(key, (n,), minval=jnp.log(self.low), maxval=jnp.log(self.high))
        value = jnp.exp(u)
        return jnp.round(value) if feature.kind == "int" else value


@dataclasses.dataclass(frozen=True)
class Normal:
    """Normal(mean, std) truncated to the feature's bounds (and to [low, high] if given)."""

    mean: float
    std: float
    low: float | None = None
    high: float | None = None

    def _range(self, feature: Feature) -> tuple[float, float]:
        low = feature.lower if self.low is None else self.low
        high = feature.upper if self.high is None else self.high
        return low, high

    def check(self, feature: Feature) -> None:
        _finite(feature, "Normal", mean=self.mean, std=self.std)
        _numeric_only(feature, "Normal")
        if self.std <= 0:
            raise ContextError(f"{feature.name}: Normal std must be > 0, got {self.std:g}")
        low, high = self._range(feature)
        _finite(feature, "Normal", low=low, high=high)
        if low > high:
            raise ContextError(
                f"{feature.name}: Normal truncation range [{low:g}, {high:g}] is empty"
            )
        _inside(feature, low, high, "Normal (truncated)")

    def sample(self, key, n: int, feature: Feature) -> jax.Array:
        low, high = self._range(feature)
        z = jax.random.truncated_normal(
            key, (low - self.mean) / self.std, (high - self.mean) / self.std, (n,)
        )
        value = jnp.clip(self.mean + self.std * z, low, high)
        return jnp.round(value) if feature.kind == "int" else value


@dataclasses.dataclass(frozen=True)
class Categorical:
    """One of ``choices`` (values, or choice names for categorical features), optionally weighted."""

    choices: Sequence[Any]
    weights: Sequence[float] | None = None

    def _values(self, feature: Feature) -> np.ndarray:
        return np.stack([feature.coerce(c) for c in self.choices])

    def check(self, feature: Feature) -> None:
        if len(self.choices) == 0:
            raise ContextError(f"{feature.name}: Categorical needs at least one choice")
        self._values(feature)
        if self.weights is not None:
            weights = np.asarray(self.weights, dtype=float)
            if weights.shape != (len(self.choices),):
                raise ContextError(
                    f"{feature.name}: Categorical has {len(self.choices)} choices "
                    f"but {weights.size} weights"
                )
            if not np.all(np.isfinite(weights)) or np.any(weights < 0) or weights.sum() <= 0:
                raise ContextError(
                    f"{feature.name}: Categorical weights must be finite, >= 0, not all 0"
                )

    def sample(self, key, n: int, feature: Feature) -> jax.Array:
        values = jnp.asarray(self._values(feature))
        p = None if self.weights is None else jnp.asarray(self.weights, jnp.float32)
        index = jax.random.choice(key, len(self.choices), (n,), p=p)
        return values[index]


@dataclasses.dataclass(frozen=True)
class Constant:
    """Always the same value."""

    value: Any

    def check(self, feature: Feature) -> None:
        if np.ndim(self.value) != 0:
            raise ContextError(
                f"{feature.name}: {self.value!r} is not a distribution; give one value, or a "
                f"distribution such as crl.Uniform(low, high) or crl.Categorical([...]) to draw from"
            )
        feature.coerce(self.value)

    def sample(self, key, n: int, feature: Feature) -> jax.Array:
        return jnp.full((n,), feature.coerce(self.value))


@dataclasses.dataclass(frozen=True)
class Scaled:
    """A constant magnitude ``A`` × the default (the paper's sensitivity sweeps, A = 0.1 … 2.2)."""

    magnitude: float

    def _value(self, feature: Feature) -> float:
        _finite(feature, "Scaled", magnitude=self.magnitude)
        _numeric_only(feature, "Scaled")
        return self.magnitude * feature.default

    def check(self, feature: Feature) -> None:
        value = self._value(feature)
        _inside(feature, value, value, f"Scaled({self.magnitude:g})")

    def sample(self, key, n: int, feature: Feature) -> jax.Array:
        return Constant(self._value(feature)).sample(key, n, feature)


@dataclasses.dataclass(frozen=True)
class RelativeUniform:
    """Uniform over [a·default, b·default] (the paper's "A ~ U(0.1, 2.2)" training distributions)."""

    a: float
    b: float

    def _absolute(self, feature: Feature) -> Uniform:
        _finite(feature, "RelativeUniform", a=self.a, b=self.b)
        _numeric_only(feature, "RelativeUniform")
        ends = sorted((self.a * feature.default, self.b * feature.default))
        return Uniform(ends[0], ends[1])

    def check(self, feature: Feature) -> None:
        if self.a > self.b:
            raise ContextError(
                f"{feature.name}: RelativeUniform is empty (a {self.a:g} > b {self.b:g})"
            )
        absolute = self._absolute(feature)
        _inside(feature, absolute.low, absolute.high, f"RelativeUniform({self.a:g}, {self.b:g})")

    def sample(self, key, n: int, feature: Feature) -> jax.Array:
        return self._absolute(feature).sample(key, n, feature)


# Their parameters are pytree data, so a compiled loop can carry them and change them between updates
# (a curriculum) without compiling again; ``check`` runs wherever they are concrete.
for _continuous in (Uniform, LogUniform, Normal):
    jax.tree_util.register_dataclass(
        _continuous,
        data_fields=[f.name for f in dataclasses.fields(_continuous)],
        meta_fields=[],
    )

Distribution = Uniform | LogUniform | Normal | Categorical | Constant | Scaled | RelativeUniform
DISTRIBUTIONS = (Uniform, LogUniform, Normal, Categorical, Constant, Scaled, RelativeUniform)


def _space_of(target: Any) -> ContextSpace:
    """Accept an env, a context class, a context instance or a space."""
    if isinstance(target, ContextSpace):
        return target
    space = getattr(target, "space", None) or getattr(
        getattr(target, "context_type", None), "space", None
    )
    if not isinstance(space, ContextSpace):
        raise TypeError(f"cannot find a context space on {target!r}")
    return space


def support(distribution: Distribution, feature: Feature) -> tuple[float, float]:
    """The smallest and largest value ``distribution`` can draw for ``feature`` (already checked)."""
    if isinstance(distribution, (Uniform, LogUniform)):
        return float(distribution.low), float(distribution.high)
    if isinstance(distribution, Normal):
        low, high = distribution._range(feature)
        return float(low), float(high)
    if isinstance(distribution, RelativeUniform):
        absolute = distribution._absolute(feature)
        return float(absolute.low), float(absolute.high)
    if isinstance(distribution, Categorical):
        values = distribution._values(feature).astype(np.float64)
        return float(values.min()), float(values.max())
    if isinstance(distribution, Scaled):
        value = distribution._value(feature)
    else:  # Constant
        value = feature.coerce(distribution.value)
    return float(value), float(value)


def check_spec(target: Any, spec: Mapping[str, Any]) -> dict[str, Distribution]:
    """Resolve names and validate every distribution against its feature; plain numbers become Constant.

    A spec that can draw a context breaking one of the space's coherence rules is refused here, so
    ``sample`` and resampling at reset never yield a context the environment would refuse.
    """
    space = _space_of(target)
    resolved: dict[str, Distribution] = {}
    for name, distribution in spec.items():
        canonical = space.resolve(name)
        if not isinstance(distribution, DISTRIBUTIONS):
            distribution = Constant(distribution)
        distribution.check(space.features[canonical])
        resolved[canonical] = distribution
    ranges = {name: support(d, space.features[name]) for name, d in resolved.items()}
    space.check_ranges(ranges, "this distribution spec")
    return resolved


def sample(target: Any, spec: Mapping[str, Any], n: int, key) -> Any:
    """``n`` contexts as one batch: features in ``spec`` drawn from their distributions, the rest default.

    Each feature draws from its own key (folded in by its declaration index), so adding a feature to the
    spec never changes the values drawn for the others.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ContextError(f"n must be a positive integer, got {n!r}")
    space = _space_of(target)
    return draw(space, check_spec(space, spec), int(n), key)


def draw(space: ContextSpace, resolved: Mapping[str, Distribution], n: int, key) -> Any:
    """``n`` contexts from an already checked spec; pure and jittable (also used at reset)."""
    values = {}
    for index, (name, f) in enumerate(space.features.items()):
        if name in resolved:
            drawn = resolved[name].sample(jax.random.fold_in(key, index), n, f)
            values[name] = jnp.asarray(drawn, f.dtype)
        else:
            values[name] = jnp.full((n,), f.default, f.dtype)
    return space.context_class(**values)
