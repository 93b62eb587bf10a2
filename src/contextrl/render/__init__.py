"""Rendering: RGB frames of environments drawn so their context is visible, and animations of them."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from contextrl.render.canvas import Canvas
from contextrl.render.classic_control import RENDERERS
from contextrl.render.platformer import PlatformerRenderer

RENDERERS = {**RENDERERS, "Platformer": PlatformerRenderer()}

FRAME_WIDTH = 600


def renderer_for(env: Any):
    """The renderer of a JAX environment, or a clear error naming the ones that exist."""
    renderer = RENDERERS.get(env.name)
    if renderer is None:
        raise NotImplementedError(
            f"no renderer for {env.name}; renderers exist for {sorted(RENDERERS)}"
        )
    return renderer


def union_box(boxes: Sequence[tuple[float, float, float, float]]) -> tuple[float, ...]:
    """The smallest world box holding every box (panels of a grid share one scale)."""
    boxes = np.asarray(boxes, float)
    return (boxes[:, 0].min(), boxes[:, 1].max(), boxes[:, 2].min(), boxes[:, 3].max())


def draw(env: Any, physics: Any, context: Any, world_box=None, width: int = FRAME_WIDTH):
    """An RGB frame (H, W, 3, uint8) of ``physics`` under ``context`` for a JAX environment (drawn by
    the environment itself when it has a ``render_state``, as the MuJoCo-based Brax tasks do)."""
    if hasattr(env, "render_state"):
        return env.render_state(physics, context)
    renderer = renderer_for(env)
    box = renderer.world_box(context) if world_box is None else world_box
    height = max(1, round(width * (box[3] - box[2]) / (box[1] - box[0])))
    canvas = Canvas(box, width=width, height=height)
    renderer.paint(canvas, physics, context)
    return canvas.frame()


__all__ = ["Canvas", "draw", "renderer_for", "union_box"]
