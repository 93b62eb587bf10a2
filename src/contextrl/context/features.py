"""Context features declared once, on the fields of a context dataclass.

A context is a frozen dataclass whose fields are JAX arrays (scalars for one context, a leading batch
axis for many). Each field carries a :class:`Feature` declaration: default, bounds, kind, unit, meaning,
what it affects and the paper's aliases. Validation, sampling, docs tables, the CLI and the environment
checker all read those declarations, so they can never disagree.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

KINDS = ("float", "int", "categorical")
EFFECTS = ("dynamics", "reward", "start_state", "goal", "observation")


class ContextError(ValueError):
    """Raised for any invalid context input: unknown feature, out-of-bounds value, NaN, wrong type."""


@dataclasses.dataclass(frozen=True)
class Feature:
    """The declaration of one context feature."""

    name: str
    default: float | int
    lower: float
    upper: float
    kind: str = "float"
    choices: tuple[str, ...] = ()
    unit: str = ""
    doc: str = ""
    affects: tuple[str, ...] = ("dynamics",)
    aliases: tuple[str, ...] = ()

    @property
    def dtype(self):
        return jnp.float32 if self.kind == "float" else jnp.int32

    @property
    def bounds(self) -> tuple[float, float]:
        return (self.lower, self.upper)

    def default_label(self) -> str:
        return (
            self.choices[int(self.default)] if self.kind == "categorical" else f"{self.default:g}"
        )

    def coerce(self, value: Any) -> np.ndarray:
        """Turn a user value (number, choice name, array) into a checked NumPy array of this kind."""
        if self.kind == "categorical" and isinstance(value, str):
            if value not in self.choices:
                raise ContextError(
                    f"{self.name}: {value!r} is not a valid choice; choose one of {list(self.choices)}"
                )
            value = self.choices.index(value)
        if isinstance(value, bool) or isinstance(value, np.bool_):
            raise ContextError(f"{self.name}: expected a number, got a bool ({value!r})")
        try:
            array = np.asarray(value)
        except Exception as error:  # pragma: no cover - numpy raises many types
            raise ContextError(f"{self.name}: cannot read {value!r} as a number") from error
        if array.dtype.kind not in "iuf":
            raise ContextError(
                f"{self.name}: expected a number, got {type(value).__name__} ({value!r})"
            )
        if array.ndim > 1:
            raise ContextError(
                f"{self.name}: expected a scalar or a 1-D batch, got shape {array.shape}"
            )
        if array.ndim == 0:
            return self._coerce_one(array, value)
        if not np.all(np.isfinite(array)):
            raise self._not_finite(array[~np.isfinite(array)].flat[0])  # the value, not the batch
        if self.kind != "float" and not np.all(np.equal(np.round(array), array)):
            raise self._not_integer(value)
        # Compared at the precision a context holds, so a stored bound value passes a second check.
        stored = array.astype(self._stored_dtype)
        lower, upper = self._stored_bounds
        low, high = np.min(stored), np.max(stored)
        if low < lower or high > upper:
            raise self._outside(np.min(array) if low < lower else np.max(array))
        return stored

    def _not_finite(self, bad) -> ContextError:
        return ContextError(f"{self.name}: value {bad:g} is not finite (NaN or inf)")

    def _not_integer(self, value) -> ContextError:
        return ContextError(f"{self.name}: expected an integer ({self.kind}), got {value!r}")

    def _outside(self, bad) -> ContextError:
        return ContextError(
            f"{self.name}: value {bad:g} is outside its bounds [{self.lower:g}, {self.upper:g}]"
        )

    @property
    def _stored_dtype(self) -> type:
        return np.float32 if self.kind == "float" else np.int32

    @functools.cached_property
    def _stored_bounds(self) -> tuple[float, float]:
        """The bounds at the precision a context holds them (as :meth:`coerce` compares)."""
        lower, upper = np.asarray([self.lower, self.upper]).astype(self._stored_dtype).tolist()
        return lower, upper

    def _coerce_one(self, array: np.ndarray, value: Any) -> np.ndarray:
        """:meth:`coerce`'s checks for one value, on Python numbers (a host environment checks
        every feature at every reset; NumPy reductions would cost microseconds each)."""
        number = array.item()
        if not math.isfinite(number):
            raise self._not_finite(number)
        if self.kind != "float" and round(number) != number:
            raise self._not_integer(value)
        stored = array.astype(self._stored_dtype)
        lower, upper = self._stored_bounds
        if not lower <= stored.item() <= upper:
            raise self._outside(number)
        return stored


def feature(
    default: float | int | str,
    lower: float,
    upper: float,
    *,
    kind: str = "float",
    choices: tuple[str, ...] = (),
    unit: str = "",
    doc: str = "",
    affects: tuple[str, ...] = ("dynamics",),
    aliases: tuple[str, ...] = (),
) -> Any:
    """Declare a context feature as a dataclass field (see :func:`context_type`, which checks the
    declaration once the feature has its name)."""
    if kind == "categorical":
        if isinstance(default, str) and default not in choices:
            default = -1  # refused by the check, with the choices named
        default = choices.index(default) if isinstance(default, str) else int(default)
        lower, upper = 0, len(choices) - 1
    spec = dict(
        default=default,
        lower=lower,
        upper=upper,
        kind=kind,
        choices=tuple(choices),
        unit=unit,
        doc=doc,
        affects=tuple(affects),
        aliases=tuple(aliases),
    )
    return dataclasses.field(default=default, metadata={"feature": spec})


def check_declaration(spec: dict) -> None:
    """What a feature declaration must satisfy: a known kind and effects, finite bounds around
    its default."""
    kind, affects = spec["kind"], spec["affects"]
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    unknown = set(affects) - set(EFFECTS)
    if unknown or not affects:
        raise ValueError(f"affects must be a non-empty subset of {EFFECTS}, got {affects!r}")
    default, lower, upper = spec["default"], spec["lower"], spec["upper"]
    if kind == "categorical" and not 0 <= default < len(spec["choices"]):
        raise ValueError(f"the default must be one of the choices {list(spec['choices'])}")
    if not (math.isfinite(lower) and math.isfinite(upper) and lower <= default <= upper):
        raise ValueError(f"default {default!r} must lie inside finite bounds [{lower}, {upper}]")


@dataclasses.dataclass(frozen=True)
class Coherence:
    """A rule a whole context must satisfy, tying features together (a goal inside the track, …).

    ``holds(*values)`` takes the features' values (NumPy arrays, in the order of ``features``) and says
    where the rule holds. Rules are linear in their features, so a distribution spec is checked at the
    corners of its features' ranges: a spec that can draw an incoherent context is refused up front.
    """

    features: tuple[str, ...]
    holds: Callable[..., Any]
    requirement: str  # the rule as users read it: "goal_position <= max_position"
    why: str  # what would go wrong otherwise


def _is_concrete(value: Any) -> bool:
    return not isinstance(value, jax.core.Tracer)


class ContextBase:
    """Methods shared by every context dataclass; the space is attached by :func:`context_type`."""

    space: ClassVar[ContextSpace]

    def replace(self, **values: Any):
        """A copy with some features changed, validated against the declarations."""
        return self.space.make(base=self, **values)

    def as_dict(self) -> dict[str, Any]:
        """Feature name to value (arrays), in declaration order."""
        return {name: getattr(self, name) for name in self.space.names}

    def as_array(self) -> jax.Array:
        return self.space.to_array(self)

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return jnp.shape(getattr(self, self.space.names[0]))

    def __getitem__(self, index):
        """Select contexts from a batch (``contexts[3]``, ``contexts[:8]``)."""
        return jax.tree_util.tree_map(lambda leaf: leaf[index], self)

    def __len__(self) -> int:
        shape = self.batch_shape
        if not shape:
            raise TypeError("a single context has no length; only a batch of contexts does")
        return shape[0]


def context_type(cls):
    """Class decorator for a ``ContextBase`` subclass: a frozen JAX pytree dataclass with its space."""
    if not issubclass(cls, ContextBase):
        raise TypeError(f"{cls.__name__} must subclass ContextBase")
    data_cls = dataclasses.dataclass(frozen=True)(cls)
    features = []
    for field in dataclasses.fields(data_cls):
        if "feature" not in field.metadata:
            raise TypeError(f"{cls.__name__}.{field.name} must be declared with feature(...)")
        spec = field.metadata["feature"]
        try:
            check_declaration(spec)
        except ValueError as error:
            raise ValueError(f"feature {field.name!r} of {data_cls.__name__}: {error}") from None
        features.append(Feature(name=field.name, **spec))
    jax.tree_util.register_dataclass(
        data_cls, data_fields=[f.name for f in features], meta_fields=[]
    )
    rules = tuple(getattr(cls, "coherence", ()))
    data_cls.space = ContextSpace(data_cls, tuple(features), rules, getattr(cls, "left_out", {}))
    # A declaration bug, caught at import; numpy values, so that importing contextrl starts no JAX
    # backend and XLA_FLAGS set afterwards (contextrl.xla_flags) still take effect.
    defaults = data_cls(**{f.name: np.asarray(f.default, f.dtype) for f in features})
    data_cls.space.check_coherence(defaults)
    return data_cls


class ContextSpace:
    """Everything known about the contexts of one environment: names, bounds, validation, conversion."""

    def __init__(
        self,
        context_class: type,
        features: tuple[Feature, ...],
        rules: tuple[Coherence, ...] = (),
        left_out: dict[str, str] | None = None,
    ):
        self.context_class = context_class
        self.rules = rules
        # features of the original environment that cannot act here, each with why: named in errors
        self.left_out: dict[str, str] = dict(left_out or {})
        for rule in rules:
            for name in rule.features:
                if name not in {f.name for f in features}:
                    raise TypeError(f"coherence rule {rule.requirement!r} names unknown {name!r}")
        self.features: dict[str, Feature] = {f.name: f for f in features}
        self.names: tuple[str, ...] = tuple(self.features)
        self._aliases = {alias: f.name for f in features for alias in f.aliases}
        self.lower = np.array([f.lower for f in features], dtype=np.float32)
        self.upper = np.array([f.upper for f in features], dtype=np.float32)

    def __repr__(self) -> str:
        return f"ContextSpace({self.context_class.__name__}, features={list(self.names)})"

    def __len__(self) -> int:
        return len(self.names)

    def resolve(self, name: str) -> str:
        """The canonical feature name for a name or a paper alias; clear error otherwise."""
        if name in self.features:
            return name
        if name in self._aliases:
            return self._aliases[name]
        aliases = f" (aliases: {sorted(self._aliases)})" if self._aliases else ""
        if name in self.left_out:
            raise ContextError(
                f"context feature {name!r} is left out of {self.context_class.__name__}: "
                f"{self.left_out[name]}; valid features: {list(self.names)}{aliases}"
            )
        raise ContextError(
            f"unknown context feature {name!r} for {self.context_class.__name__}; "
            f"valid features: {list(self.names)}{aliases}"
        )

    def default(self):
        """The default context: the original environment."""
        return self.context_class(
            **{n: jnp.asarray(f.default, dtype=f.dtype) for n, f in self.features.items()}
        )

    def make(self, base=None, **values: Any):
        """A validated context from feature values (names or aliases); the rest from ``base`` or defaults.

        Every value is checked before anything is built, so a bad call changes nothing.
        """
        checked = {}
        for name, value in values.items():
            canonical = self.resolve(name)
            if canonical in checked:
                raise ContextError(f"{canonical} given twice (once through an alias)")
            if _is_concrete(value):
                value = jnp.asarray(self.features[canonical].coerce(value))
            checked[canonical] = value
        base = self.default() if base is None else base
        merged = {**base.as_dict(), **checked}
        batch_shapes = {jnp.shape(v) for v in merged.values()} - {()}
        if len(batch_shapes) > 1:
            raise ContextError(f"features have different batch shapes: {sorted(batch_shapes)}")
        if batch_shapes:  # one batched value makes a batch: the scalar features repeat along it
            (shape,) = batch_shapes
            merged = {n: jnp.broadcast_to(v, shape) for n, v in merged.items()}
        context = self.context_class(**merged)
        self.check_coherence(context)
        return context

    def check_coherence(self, context) -> None:
        """Raise ContextError naming the features of the first rule a (batch of) context(s) breaks."""
        for rule in self.rules:
            values = [getattr(context, name) for name in rule.features]
            if not all(_is_concrete(v) for v in values):
                continue
            arrays = [np.asarray(v, np.float64) for v in values]
            broken = ~np.broadcast_to(np.asarray(rule.holds(*arrays), bool), np.shape(arrays[0]))
            if broken.any():
                where = (
                    np.unravel_index(int(np.argmax(broken)), broken.shape) if broken.ndim else ()
                )
                got = ", ".join(
                    f"{n}={float(a[where]):g}" for n, a in zip(rule.features, arrays, strict=True)
                )
                at = f" (context {where[0]} of the batch)" if where else ""
                raise ContextError(
                    f"{self.context_class.__name__}: {rule.requirement} is required ({rule.why}); "
                    f"got {got}{at}"
                )

    def check_ranges(self, ranges: Mapping[str, tuple[float, float]], what: str) -> None:
        """Refuse value ranges (feature → (low, high); others at their default) that let a rule break.

        The rules are linear, so checking every corner of the ranges of a rule's features is exact.
        """
        for rule in self.rules:
            spans = [ranges.get(n, (float(self.features[n].default),) * 2) for n in rule.features]
            for corner in itertools.product(*spans):
                if not bool(rule.holds(*(np.float64(v) for v in corner))):
                    reach = ", ".join(
                        f"{n} in [{low:g}, {high:g}]"
                        for n, (low, high) in zip(rule.features, spans, strict=True)
                    )
                    raise ContextError(
                        f"{self.context_class.__name__}: {what} can draw contexts that break "
                        f"{rule.requirement} ({rule.why}): {reach}"
                    )

    def from_dict(self, values: Mapping[str, Any]):
        return self.make(**dict(values))

    def check(self, context) -> None:
        """Validate every feature of a (possibly batched) concrete context; raise ContextError."""
        if not isinstance(context, self.context_class):
            raise ContextError(
                f"expected a {self.context_class.__name__}, got {type(context).__name__}"
            )
        for name, f in self.features.items():
            value = getattr(context, name)
            if _is_concrete(value):
                f.coerce(np.asarray(value))
        self.check_coherence(context)

    def to_array(self, context) -> jax.Array:
        """Features stacked on the last axis as float32, in declaration order."""
        return jnp.stack(
            [jnp.asarray(getattr(context, n), jnp.float32) for n in self.names], axis=-1
        )

    def from_array(self, array) -> Any:
        """Inverse of :meth:`to_array` (values are not re-validated; use :meth:`check`)."""
        array = jnp.asarray(array)
        if array.shape[-1:] != (len(self.names),):
            raise ContextError(
                f"expected an array whose last axis has {len(self.names)} entries "
                f"({list(self.names)}), got shape {array.shape}"
            )
        return self.context_class(
            **{n: array[..., i].astype(f.dtype) for i, (n, f) in enumerate(self.features.items())}
        )

    def to_dict(self, context) -> dict[str, Any]:
        """Plain Python values (lists for batches); categorical features as their choice names."""
        out = {}
        for name, f in self.features.items():
            value = np.asarray(getattr(context, name))
            if f.kind == "categorical":
                out[name] = (
                    f.choices[int(value)] if value.ndim == 0 else [f.choices[int(v)] for v in value]
                )
            else:
                out[name] = value.item() if value.ndim == 0 else value.tolist()
        return out

    def to_gymnasium(self):
        """A gymnasium Box holding every context as a float32 vector in declaration order."""
        import gymnasium

        return gymnasium.spaces.Box(self.lower, self.upper, dtype=np.float32)

    def stack(self, contexts) -> Any:
        """One batched context from a sequence of single contexts."""
        contexts = list(contexts)
        if not contexts:
            raise ContextError("cannot stack an empty list of contexts")
        return jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *contexts)

    def varying(self, contexts) -> tuple[str, ...]:
        """Names of the features whose value differs somewhere in a batch of contexts."""
        return tuple(n for n in self.names if np.unique(np.asarray(getattr(contexts, n))).size > 1)
