"""Host environments: the same context model for simulators that cannot be JAX functions.

Box2D, MuJoCo through dm_control, RNA folding and the platformer step on the CPU. They declare their
context exactly like JAX environments (a ``context_type`` of features), and the gymnasium adapter gives
them the same context sets, selectors, observation options and time limit. A host environment only
writes how a context is applied and how the simulator steps; it is vectorised across processes.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from contextrl.context.features import ContextError
from contextrl.core.env import ContextHelpers


class HostEnv(ContextHelpers):
    """Base of every CPU-stepped environment. Stateful (it wraps a simulator), but seeded explicitly.

    The adapter calls ``reset_physics(context, rng)`` at every reset with the episode's (validated,
    unbatched) context and a ``numpy.random.Generator`` seeded from ``reset(seed=...)``, then
    ``step_physics(action)`` until the episode ends. The time limit and the context observation are the
    adapter's business, not the environment's.
    """

    default_max_steps: ClassVar[int]
    # Set by each host environment's ``__init__`` (they depend on its options, e.g. continuous or not):
    action_space: Any  # a gymnasium space
    base_observation_space: Any  # a gymnasium Box holding the original observation in every context

    def context_values(self, context: Any) -> dict[str, float]:
        """One unbatched context as plain floats, checked by ``context_space.check`` (type, finite,
        bounds, coherence) and refused when a feature holds more than one value."""
        self.context_space.check(context)
        values = {}
        for name in self.context_space.names:
            value = np.asarray(getattr(context, name))
            if value.ndim != 0:
                raise ContextError(
                    f"{self.name}: {name} must be one value per episode, got shape {value.shape}"
                )
            values[name] = float(value)
        return values

    # ---- written by each host environment ------------------------------------------------------------
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
