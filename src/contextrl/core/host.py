"""Host environments: the same context model for simulators that cannot be JAX functions.

Box2D, MuJoCo through dm_control, RNA folding and the platformer step on the CPU. They declare their
context exactly like JAX environments (a ``context_type`` of features), and the gymnasium adapter gives
them the same context sets, selectors, observation options and time limit. A host environment only
writes how a context is applied and how the simulator steps; it is vectorised across processes.
"""

from __future__ import annotations

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
        """One unbatched context as plain floats, checked (type, one value each, finite, bounds).

        The checks of ``context_space.check`` written for one context, cheap enough for every reset.
        """
        if not isinstance(context, self.context_type):
            raise ContextError(
                f"{self.name}: expected a {self.context_type.__name__}, got {type(context).__name__}"
            )
        values = {}
        for name, feature in self.context_space.features.items():
            value = np.asarray(getattr(context, name))
            if value.ndim != 0:
                raise ContextError(
                    f"{self.name}: {name} must be one value per episode, got shape {value.shape}"
                )
            value = float(value)
            if not math.isfinite(value):
                raise ContextError(f"{name}: value {value!r} is not finite (NaN or inf)")
            lower, upper = float(np.float32(feature.lower)), float(np.float32(feature.upper))
            if not lower <= value <= upper:  # compared as float32, the precision a context holds
                raise ContextError(
                    f"{name}: value {value:g} is outside its bounds "
                    f"[{feature.lower:g}, {feature.upper:g}]"
                )
            values[name] = value
        return values

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

    def step_info(self) -> dict[str, Any]:
        """Entries the gymnasium adapter adds to ``info`` after each reset and step (none by default)."""
        return {}

    def render_frame(self) -> np.ndarray:
        """An RGB frame (H, W, 3, uint8) of the current state."""
        raise NotImplementedError

    def close(self) -> None:
        """Release simulator resources."""
