"""What an agent's configuration must satisfy: ``ConfigError`` and the checks every config uses.

A configuration is checked when it is built into a training function, before anything is compiled, and
each refusal names the field, the value and what is valid.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import numpy as np


class ConfigError(ValueError):
    """An invalid agent configuration, raised before anything is compiled."""


def check_positive(
    name: str, value: Any, *, integer: bool = False, allow_zero: bool = False
) -> None:
    """Refuse a non-finite, wrongly typed, negative (or zero) configuration value with a clear error.
    A traced value passes: it is a hyper-parameter checked as a number before it was traced."""
    if isinstance(value, jax.core.Tracer):
        return
    kinds = (int, np.integer) if integer else (int, float, np.integer, np.floating)
    if isinstance(value, bool) or not isinstance(value, kinds):
        kind = "an integer" if integer else "a number"
        raise ConfigError(f"{name} must be {kind}, got {value!r}")
    if not math.isfinite(value):
        raise ConfigError(f"{name} must be finite, got {value!r}")
    if value < 0 or (value == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ConfigError(f"{name} must be {bound}, got {value!r}")


def check_fraction(name: str, value: Any, *, include_one: bool = True) -> None:
    """Refuse a value outside [0, 1] (or [0, 1))."""
    check_positive(name, value, allow_zero=True)
    if isinstance(value, jax.core.Tracer):
        return
    if value > 1 or (value == 1 and not include_one):
        raise ConfigError(f"{name} must be in [0, 1{']' if include_one else ')'}, got {value!r}")


def flat_observation_size(agent: str, observation_space: Any) -> int:
    """The length of a flat (1-D) observation, which every agent's networks take; refused otherwise."""
    shape = observation_space.shape
    if len(shape) != 1:
        raise ConfigError(f"{agent} needs a flat (1-D) observation, got shape {shape}")
    return int(shape[0])
