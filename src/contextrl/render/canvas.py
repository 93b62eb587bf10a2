"""A tiny NumPy rasteriser (filled polygons, circles, thick lines) so rendering needs no GUI library.

Coordinates are in world units; the canvas maps a world rectangle onto pixels with y pointing up, the
way physics is written, and flips it when the frame is read.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

Color = tuple[int, int, int]


class Canvas:
    """An RGB image onto which world-space shapes are drawn."""

    def __init__(
        self,
        world_box: tuple[float, float, float, float],
        width: int = 600,
        height: int = 400,
        background: Color = (255, 255, 255),
    ):
        """``world_box`` is (x_min, x_max, y_min, y_max) in world units, mapped onto the whole image."""
        self.x_min, self.x_max, self.y_min, self.y_max = (float(v) for v in world_box)
        if not (self.x_max > self.x_min and self.y_max > self.y_min):
            raise ValueError(
                f"world_box must have x_max > x_min and y_max > y_min, got {world_box}"
            )
        self.width, self.height = int(width), int(height)
        self.pixels = np.empty((self.height, self.width, 3), np.uint8)
        self.pixels[:] = background
        # Pixel centres in world coordinates (row 0 is the bottom of the world box).
        xs = self.x_min + (np.arange(self.width) + 0.5) * (self.x_max - self.x_min) / self.width
        ys = self.y_min + (np.arange(self.height) + 0.5) * (self.y_max - self.y_min) / self.height
        self._x, self._y = xs[None, :], ys[:, None]
        self.scale = self.width / (self.x_max - self.x_min)  # pixels per world unit (x)

    def _window(self, x_low, x_high, y_low, y_high):
        """Index slices of the pixels whose centres may lie in a world rectangle."""
        span_x = (self.x_max - self.x_min) / self.width
        span_y = (self.y_max - self.y_min) / self.height
        c0 = int(np.clip(np.floor((x_low - self.x_min) / span_x), 0, self.width))
        c1 = int(np.clip(np.ceil((x_high - self.x_min) / span_x) + 1, 0, self.width))
        r0 = int(np.clip(np.floor((y_low - self.y_min) / span_y), 0, self.height))
        r1 = int(np.clip(np.ceil((y_high - self.y_min) / span_y) + 1, 0, self.height))
        return slice(r0, r1), slice(c0, c1)

    def polygon(self, points: Sequence[tuple[float, float]], color: Color) -> None:
        """Fill a convex polygon (vertices in either winding order)."""
        pts = np.asarray(points, float)
        rows, cols = self._window(
            pts[:, 0].min(), pts[:, 0].max(), pts[:, 1].min(), pts[:, 1].max()
        )
        x, y = self._x[:, cols], self._y[rows, :]
        inside_pos = np.ones((y.shape[0], x.shape[1]), bool)
        inside_neg = inside_pos.copy()
        for (x0, y0), (x1, y1) in zip(pts, np.roll(pts, -1, axis=0), strict=True):
            cross = (x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)
            inside_pos &= cross >= 0
            inside_neg &= cross <= 0
        self.pixels[rows, cols][inside_pos | inside_neg] = color  # slices: a view, drawn in place

    def circle(self, center: tuple[float, float], radius: float, color: Color) -> None:
        cx, cy = center
        rows, cols = self._window(cx - radius, cx + radius, cy - radius, cy + radius)
        x, y = self._x[:, cols], self._y[rows, :]
        mask = (x - cx) ** 2 + (y - cy) ** 2 <= radius**2
        self.pixels[rows, cols][mask] = color

    def line(self, start, end, width: float, color: Color) -> None:
        """A thick segment of ``width`` world units (at least 1.5 pixels) with round ends."""
        (x0, y0), (x1, y1) = start, end
        width = max(width, 1.5 / self.scale)  # never thinner than a pixel and a half
        length = float(np.hypot(x1 - x0, y1 - y0))
        half = width / 2
        if length > 0:
            nx, ny = -(y1 - y0) / length * half, (x1 - x0) / length * half
            self.polygon(
                [(x0 + nx, y0 + ny), (x1 + nx, y1 + ny), (x1 - nx, y1 - ny), (x0 - nx, y0 - ny)],
                color,
            )
        self.circle(start, half, color)
        self.circle(end, half, color)

    def frame(self) -> np.ndarray:
        """The image as (height, width, 3) uint8, top row first."""
        return self.pixels[::-1].copy()
