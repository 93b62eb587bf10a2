"""Host environments: the same context model for simulators that cannot be JAX functions.

Box2D, MuJoCo through dm_control, RNA folding and the platformer step on the CPU. They declare their
context exactly like JAX environments (a ``context_type`` of features), and the gymnasium adapter gives
them the same context sets, selectors, observation options and time limit. A host environment only
writes how a context is applied and how the simulator steps; it is vectorised across processes.
"""

from __future__ import annotations

import functools
import math
from typing import Any, ClassVar

import numpy as np

from contextrl.context.features import ContextError


class HostEnv:
    """Base of every CPU-stepped environment. Stateful (it wraps a simulator), but seeded explicitly.

    The adapter calls ``reset_physics(context, rng)`` at every reset with the episode's (validated,
    unbatched) context and a ``numpy.random.Generator`` seeded from ``reset(seed=...)``, then
    ``step_physics(action)`` until the episode ends. The time limit and the context observation are the
    adapter's business, not the environment's.
    """

    context_type: ClassVar[type]
    default_max_steps: ClassVar[int]

    @property
    def name(self) -> str:
        return type(self).__name__

    @property
    def context_space(self):
        return self.context_type.space

    def default_context(self):
        return self.context_space.default()

    def context(self, **values):
        return self.context_space.make(**values)

    def context_values(self, context: Any) -> dict[str, float]:
        """The context as plain floats, checked (type, bounds, finite, unbatched, valid combination).

        The same checks as ``context_space.check``, written for one unbatched context so that a
        context switch stays far below a millisecond. A value whose float32 rounding is the declared
        default's (a context holds float32) becomes the declared default itself, so a default like
        ``14 / 30`` reaches the simulator exactly as the original environment has it.
        """
        if not isinstance(context, self.context_type):
            raise ContextError(
                f"{self.name}: expected a {self.context_type.__name__}, got {type(context).__name__}"
            )
        values = {}
        for name, lower, upper, default, default32 in _feature_table(self.context_type):
            value = np.asarray(getattr(context, name))
            if value.ndim != 0:
                raise ContextError(
                    f"{self.name}: {name} must be one value per episode, got shape {value.shape}"
                )
            value = float(value)
            if not math.isfinite(value):
                raise ContextError(f"{name}: value {value!r} is not finite (NaN or inf)")
            if not lower <= value <= upper:  # compared as float32, the precision a context holds
                feature = self.context_space.features[name]
                raise ContextError(
                    f"{name}: value {value:g} is outside its bounds "
                    f"[{feature.lower:g}, {feature.upper:g}]"
                )
            values[name] = default if value == default32 else value
        self._check_combination(values)
        return values

    def _check_combination(self, values: dict[str, float]) -> None:
        """Raise ContextError for physically impossible combinations (environments override)."""

    # ---- written by each host environment ------------------------------------------------------------
    @property
    def action_space(self):
        """A gymnasium space."""
        raise NotImplementedError

    @property
    def base_observation_space(self):
        """A gymnasium Box holding the original observation for every context inside the bounds."""
        raise NotImplementedError

    def reset_physics(self, context: Any, rng: np.random.Generator) -> np.ndarray:
        """Apply ``context`` to the simulator, start an episode, return the first observation."""
        raise NotImplementedError

    def step_physics(self, action) -> tuple[np.ndarray, float, bool]:
        """``(observation, reward, terminated)`` for one action under the current context."""
        raise NotImplementedError

    def render_frame(self) -> np.ndarray:
        """An RGB frame (H, W, 3, uint8) of the current state."""
        raise NotImplementedError

    def close(self) -> None:
        """Release simulator resources."""


@functools.cache
def _feature_table(context_type: type) -> tuple[tuple[str, float, float, float, float], ...]:
    """Per feature: name, float32 bounds, declared default and its float32 rounding."""
    return tuple(
        (
            name,
            float(np.float32(f.lower)),
            float(np.float32(f.upper)),
            float(f.default),
            float(np.float32(f.default)),
        )
        for name, f in context_type.space.features.items()
    )
