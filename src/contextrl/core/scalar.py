"""A tiny array namespace over Python floats, so one environment's physics runs on the host too.

Classic-control environments write their transition and observation once against a namespace ``xp``:
``jax.numpy`` for the compiled, batched path and this module for stepping one environment from Python,
where a plain scalar step costs a few microseconds and a compiled call about fifteen. Only what those
equations use is here, with ``jax.numpy``'s meaning: ``where`` picks (both sides already computed),
``clip`` is ``min(max(x, low), high)``, ``stack`` builds a :class:`Vector`.

An environment that offers the host path defines ``host_transition(state, action, context) ->
(next_state, reward, terminated)`` and ``host_observe(state, context) -> sequence of floats`` on plain
floats (``context`` has one float attribute per feature). Only deterministic steps run on the host: a
step that draws random numbers draws them from the JAX key, in the compiled path. The gymnasium adapter
runs these as one more host simulator (``contextrl.gymnasium.backends.ScalarPhysics``).
"""

from __future__ import annotations

import builtins
import math
from collections.abc import Iterable
from typing import Any

pi = math.pi
cos = math.cos
sin = math.sin
ceil = math.ceil
abs = builtins.abs
float32 = float  # the host computes in double precision; callers round results to float32


class Vector(tuple):
    """A small tuple of floats with elementwise arithmetic (``+ - * /`` with vectors or scalars)."""

    __slots__ = ()

    def __add__(self, other: Any) -> Vector:
        if isinstance(other, tuple):
            return Vector([a + b for a, b in zip(self, other, strict=True)])
        return Vector([a + other for a in self])

    __radd__ = __add__

    def __sub__(self, other: Any) -> Vector:
        if isinstance(other, tuple):
            return Vector([a - b for a, b in zip(self, other, strict=True)])
        return Vector([a - other for a in self])

    def __rsub__(self, other: Any) -> Vector:
        return Vector([other - a for a in self])

    def __mul__(self, other: Any) -> Vector:
        if isinstance(other, tuple):
            return Vector([a * b for a, b in zip(self, other, strict=True)])
        return Vector([a * other for a in self])

    __rmul__ = __mul__

    def __truediv__(self, other: Any) -> Vector:
        if isinstance(other, tuple):
            return Vector([a / b for a, b in zip(self, other, strict=True)])
        return Vector([a / other for a in self])


def stack(values: Iterable[float]) -> Vector:
    return Vector(values)


def where(condition: bool, on_true: Any, on_false: Any) -> Any:
    return on_true if condition else on_false


def clip(x: float, low: float, high: float) -> float:
    return min(max(x, low), high)


def zeros(shape: tuple[()], dtype: type = float) -> Any:
    """A scalar zero of ``dtype`` (``zeros((), bool)`` is False); only shape () exists here."""
    if shape != ():
        raise ValueError(f"the scalar namespace has only shape (), got {shape!r}")
    return dtype(0)
