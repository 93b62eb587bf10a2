"""Animations: panels side by side with a caption each, written as a GIF (Pillow, the render extra)."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np


def _pillow():
    try:
        from PIL import Image, ImageDraw
    except ImportError as error:  # pragma: no cover - depends on the installed extras
        raise ImportError(
            "writing animations needs Pillow: pip install 'contextrl[render]'"
        ) from error
    return Image, ImageDraw


def side_by_side(panels: Sequence[np.ndarray], labels: Sequence[str] = ()) -> np.ndarray:
    """One RGB image of equally tall panels in a row, each with its caption drawn on top."""
    if not panels:
        raise ValueError("side_by_side needs at least one panel")
    height = max(p.shape[0] for p in panels)
    padded = []
    for panel in panels:
        canvas = np.full((height, panel.shape[1], 3), 255, np.uint8)
        canvas[: panel.shape[0]] = panel
        padded.append(canvas)
    separator = np.full((height, 4, 3), 160, np.uint8)
    row = [padded[0]]
    for panel in padded[1:]:
        row += [separator, panel]
    image = np.concatenate(row, axis=1)
    if labels:
        Image, ImageDraw = _pillow()
        picture = Image.fromarray(image)
        draw = ImageDraw.Draw(picture)
        x = 0
        for panel, label in zip(padded, labels, strict=True):
            draw.text((x + 8, 6), label, fill=(0, 0, 0))
            x += panel.shape[1] + separator.shape[1]
        image = np.asarray(picture)
    return image


def write_gif(frames: Sequence[np.ndarray], path: str | os.PathLike, fps: int) -> Path:
    """Write frames as a looping GIF, atomically (a temporary file renamed into place)."""
    if not frames:
        raise ValueError("write_gif needs at least one frame")
    if fps < 1:
        raise ValueError(f"fps must be a positive integer, got {fps!r}")
    Image, _ = _pillow()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    images = [Image.fromarray(np.asarray(frame, np.uint8)) for frame in frames]
    handle, temporary = tempfile.mkstemp(suffix=".gif", dir=path.parent)
    os.close(handle)
    try:
        images[0].save(
            temporary,
            format="GIF",
            save_all=True,
            append_images=images[1:],
            duration=max(20, round(1000 / fps)),
            loop=0,
        )
        os.replace(temporary, path)
    finally:
        if os.path.exists(temporary):
            os.remove(temporary)
    return path
