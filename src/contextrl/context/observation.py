"""How much of the context the agent sees: hidden, all features, a subset, normalised, noisy.

This is the one transform from a context to agent input ("obs_context"): environments append it to
their observation (``obs_context_features=``), agents feed it to their networks (their ``variant``).

Hidden (no features) keeps the observation exactly the original environment's. Visible features are
appended to it; normalised values are mapped to [0, 1] by the feature bounds; noise multiplies each value
by (1 + noise · N(0, 1)) per observation (the paper's noisy-context challenge) and is clipped to bounds so
the observation stays inside its space.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import ContextError, ContextSpace

OBS_MODES = ("all", "varying")


@dataclasses.dataclass(frozen=True)
class ContextObservation:
    """The visible features (empty: hidden), whether to normalise them, and relative noise."""

    features: tuple[str, ...] = ()
    normalize: bool = False
    noise: float = 0.0

    @classmethod
    def build(
        cls,
        space: ContextSpace,
        features: None | str | Sequence[str] = None,
        *,
        contexts: Any = None,
        normalize: bool = False,
        noise: float = 0.0,
    ) -> ContextObservation:
        """Resolve a user choice (None, "all", "varying", or names) against a context space."""
        if (
            isinstance(noise, bool)
            or not isinstance(noise, (int, float))
            or not math.isfinite(noise)
        ):
            raise ContextError(f"context observation noise must be a finite number, got {noise!r}")
        if noise < 0:
            raise ContextError(f"context observation noise must be >= 0, got {noise!r}")
        if features is None:
            names: tuple[str, ...] = ()
        elif features == "all":
            names = space.names
        elif features == "varying":
            if contexts is None:
                raise ContextError(
                    'obs_context_features="varying" needs the context set (contexts=...)'
                )
            names = space.varying(contexts)
        elif isinstance(features, str):
            raise ContextError(
                f"unknown context observation mode {features!r}; use None, {list(OBS_MODES)} "
                "or a list of feature names"
            )
        else:
            names = tuple(space.resolve(n) for n in features)
            if len(set(names)) != len(names):
                raise ContextError(f"context observation lists a feature twice: {list(features)}")
        return cls(features=names, normalize=bool(normalize), noise=float(noise))

    @property
    def hidden(self) -> bool:
        return not self.features

    def _bounds(self, space: ContextSpace) -> tuple[np.ndarray, np.ndarray]:
        index = [space.names.index(n) for n in self.features]
        return space.lower[index], space.upper[index]

    def bounds(self, space: ContextSpace) -> tuple[np.ndarray, np.ndarray]:
        """Low and high of the appended part of the observation."""
        low, high = self._bounds(space)
        if self.normalize:
            return np.zeros_like(low), np.ones_like(high)
        return low, high

    def values(self, space: ContextSpace, context: Any, key=None) -> jax.Array:
        """The appended vector of a context (float32, features on the last axis; a batch of contexts
        gives one row each); ``key`` is needed only when noisy."""
        values = jnp.stack(
            [jnp.asarray(getattr(context, n), jnp.float32) for n in self.features], axis=-1
        )
        if self.noise > 0:
            low, high = self._bounds(space)
            values = values * (1.0 + self.noise * jax.random.normal(key, values.shape))
            values = jnp.clip(values, low, high)
        return self.normalized(space, values) if self.normalize else values

    def normalized(self, space: ContextSpace, values):
        """Feature values (features on the last axis) mapped to [0, 1] by their bounds: the one
        normaliser of the context as agent input, for env observations and agents alike."""
        low, high = self._bounds(space)
        span = np.where(high > low, high - low, 1.0).astype(np.float32)
        return jnp.clip((values - low) / span, 0.0, 1.0)
