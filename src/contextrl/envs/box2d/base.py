"""What LunarLander and BipedalWalker share: checked contexts and actions, the time step, drawing.

Both worlds are built by the instance at every reset from the episode's context, so no value lives
in a module global; the random numbers come from the ``numpy.random.Generator`` of the reset, drawn in
the order gymnasium draws them, which makes the default context gymnasium's environment step by step.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from contextrl.context.features import feature
from contextrl.core.host import HostEnv
from contextrl.render.canvas import Canvas


def sign(value: float) -> float:
    """``numpy.sign`` for one float: -1.0, 0.0 or 1.0."""
    return (value > 0) - (value < 0) + 0.0


class Box2DEnv(HostEnv):
    """A Box2D world rebuilt from the context at every reset and stepped ``FPS`` times per second."""

    def __init__(self) -> None:
        self._values: dict[str, float] = self.context_values(self.default_context())
        self._rng: np.random.Generator | None = None

    def context_values(self, context: Any) -> dict[str, float]:
        """The checked values, a float32 rounding of a declared default (a context holds float32)
        given back as that default, so ``14 / 30`` reaches Box2D exactly as gymnasium has it."""
        values = super().context_values(context)
        for name, default, rounded in _defaults(self.context_type):
            if values[name] == rounded:
                values[name] = default
        return values

    @property
    def control_timestep(self) -> float:
        """Seconds of simulated time per action: ``1 / FPS`` of the current episode."""
        return 1.0 / self._values["FPS"]

    def _start(self, context: Any, rng: np.random.Generator) -> dict[str, float]:
        """The checked values of ``context``, kept for the episode with its generator."""
        values = self.context_values(context)  # every check before anything changes
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"{self.name}: rng must be a numpy.random.Generator, got {rng!r}")
        self._values, self._rng = values, rng
        return values

    def _continuous_action(self, action, size: int) -> list[float]:
        """A continuous action as ``size`` Python floats (float32 values), checked, not clipped."""
        try:
            array = np.asarray(action, dtype=np.float32)
        except (TypeError, ValueError) as error:
            raise ValueError(f"{self.name}: action {action!r} is not a numeric array") from error
        if array.shape != (size,):
            raise ValueError(f"{self.name}: action must have shape ({size},), got {array.shape}")
        values = array.tolist()
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"{self.name}: action {values} is not finite (NaN or inf)")
        return values

    def _canvas(self, x_min: float, background: tuple[int, int, int]) -> Canvas:
        """A canvas showing the viewport of the current context from ``x_min`` (world units)."""
        values = self._values
        width, height = int(values["VIEWPORT_W"]), int(values["VIEWPORT_H"])
        scale = values["SCALE"]
        box = (x_min, x_min + width / scale, 0.0, height / scale)
        return Canvas(box, width=width, height=height, background=background)


def fps_feature() -> Any:
    """``FPS`` as both gymnasium Box2D tasks declare it: one physics step per action."""
    return feature(
        50.0,
        1.0,
        500.0,
        unit="1/s",
        doc="physics steps (and actions) per second",
        affects=("dynamics", "observation", "reward"),
    )


def paint_body(canvas: Canvas, body, fill: tuple[int, int, int], outline: tuple[int, int, int]):
    """Every polygon fixture of ``body`` filled, with an outline one pixel wide."""
    transform = body.transform
    for fixture in body.fixtures:
        points = [tuple(transform * v) for v in fixture.shape.vertices]
        canvas.polygon(points, fill)
        for start, end in zip(points, points[1:] + points[:1], strict=True):
            canvas.line(start, end, 1.0 / canvas.scale, outline)


@functools.cache
def _defaults(context_type: type) -> tuple[tuple[str, float, float], ...]:
    """Per feature: name, declared default and its float32 rounding."""
    return tuple(
        (name, float(f.default), float(np.float32(f.default)))
        for name, f in context_type.space.features.items()
    )
