"""Full frames of the platformer: the JAX sprite picture of 32 × 16 tiles following the agent.

The world box only sets the picture's proportions (32 × 16 tiles); the view scrolls with the agent, so
side-by-side panels (one per context) show each level around its own agent.
"""

from __future__ import annotations

import jax
import numpy as np

from contextrl.envs.platformer import sprites
from contextrl.envs.platformer.world import ROWS
from contextrl.render.canvas import Canvas

VIEW_COLUMNS = 32
TILE_PIXELS = 16

_draw = jax.jit(
    lambda state, context: sprites.draw_view(state, context, VIEW_COLUMNS, ROWS, TILE_PIXELS)
)


class PlatformerRenderer:
    """Blits the JAX picture onto the canvas, resized to the canvas's pixels."""

    def world_box(self, context) -> tuple[float, float, float, float]:
        return (0.0, float(VIEW_COLUMNS), 0.0, float(ROWS))

    def paint(self, canvas: Canvas, physics, context) -> None:
        picture = np.asarray(_draw(physics, context))[::-1]  # the canvas keeps row 0 at the bottom
        rows = np.arange(canvas.height) * picture.shape[0] // canvas.height
        columns = np.arange(canvas.width) * picture.shape[1] // canvas.width
        canvas.pixels[:] = picture[rows[:, None], columns[None, :]]
