"""Animations: panels side by side with a caption each, written as a GIF (Pillow, the render extra)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from contextrl.core.files import atomic_write


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
            # Black on a white box: readable on a dark frame (LunarLander's sky) as on a light one.
            left, top, right, bottom = draw.textbbox((x + 8, 6), label)
            draw.rectangle((left - 3, top - 3, right + 3, bottom + 3), fill=(255, 255, 255))
            draw.text((x + 8, 6), label, fill=(0, 0, 0))
            x += panel.shape[1] + separator.shape[1]
        image = np.asarray(picture)
    return image


# A GIF's frame lasts a whole number of centiseconds, and browsers slow frames under 20 ms down to
# 100 ms: 50 frames per second is the fastest a GIF plays as written.
GIF_MAX_FPS = 50


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
    duration = max(1000 // GIF_MAX_FPS, round(1000 / fps))

    def write(temporary: str) -> None:
        images[0].save(
            temporary,
            format="GIF",
            save_all=True,
            append_images=images[1:],
            duration=duration,
            loop=0,
        )

    atomic_write(path, write)
    return path


ANIMATION_FORMATS = {".gif": "an animated GIF", ".png": "a still PNG of the first frame"}


def animation_format(path: str | os.PathLike) -> str:
    """The format the suffix of ``path`` names (a key of ``ANIMATION_FORMATS``), or a clear error."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in ANIMATION_FORMATS:
        choices = ", ".join(f"{s} ({what})" for s, what in ANIMATION_FORMATS.items())
        raise ValueError(f"--out {path}: unknown suffix {path.suffix!r}; choose one of {choices}")
    return suffix


def write_animation(frames: Sequence[np.ndarray], path: str | os.PathLike, fps: int) -> Path:
    """Write ``frames`` in the format the suffix of ``path`` names (see ``ANIMATION_FORMATS``)."""
    if animation_format(path) == ".gif":
        return write_gif(frames, path, fps)
    if not frames:
        raise ValueError("write_animation needs at least one frame")
    Image, _ = _pillow()
    still = Image.fromarray(np.asarray(frames[0], np.uint8))
    return atomic_write(Path(path), lambda temporary: still.save(temporary, format="PNG"))
