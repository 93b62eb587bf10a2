"""Pictures of the five classic-control tasks drawn from their state *and* context.

Each picture is in world units, so a context is visible: a longer pole is drawn longer, a moved goal
flag stands elsewhere, longer acrobot links reach further. ``world_box`` gives the picture's extent for a
context; side-by-side grids draw every panel in the union of their boxes so sizes compare.
"""

from __future__ import annotations

import math

import numpy as np

from contextrl.render.canvas import Canvas

BOX_COLOR = (202, 152, 101)
POLE_COLOR = (129, 132, 203)
AXLE_COLOR = (31, 31, 31)
TRACK_COLOR = (0, 0, 0)
LINK_COLOR = (0, 204, 204)
FLAG_COLOR = (204, 204, 0)
CAR_COLOR = (0, 0, 0)
ROD_COLOR = (204, 77, 77)

CART_X_THRESHOLD = 2.4


def _value(context, name: str) -> float:
    return float(np.asarray(getattr(context, name)))


class CartPoleRenderer:
    """The cart on its track and the pole at its real length (``2 × length``)."""

    aspect = 400 / 600

    def world_box(self, context) -> tuple[float, float, float, float]:
        half_width = CART_X_THRESHOLD * 1.25
        top = max(3.5, 2 * _value(context, "length") + 0.5)
        width = 2 * half_width
        height = max(top + 0.5, width * self.aspect)
        return (-half_width, half_width, -0.5, height - 0.5)

    def paint(self, canvas: Canvas, physics, context) -> None:
        x, _, theta, _ = (float(v) for v in np.asarray(physics))
        cart_w, cart_h = 0.5, 0.3
        canvas.line((canvas.x_min, 0.0), (canvas.x_max, 0.0), 0.01, TRACK_COLOR)
        canvas.polygon(
            [
                (x - cart_w / 2, 0.0),
                (x + cart_w / 2, 0.0),
                (x + cart_w / 2, cart_h),
                (x - cart_w / 2, cart_h),
            ],
            BOX_COLOR,
        )
        pivot = (x, cart_h * 0.75)
        pole = 2 * _value(context, "length")
        tip = (pivot[0] + pole * math.sin(theta), pivot[1] + pole * math.cos(theta))
        canvas.line(pivot, tip, 0.1, POLE_COLOR)
        canvas.circle(pivot, 0.05, AXLE_COLOR)


class PendulumRenderer:
    """The rod at its length ``l``, hanging from the centre; upright is angle 0."""

    aspect = 1.0

    def world_box(self, context) -> tuple[float, float, float, float]:
        bound = max(2.2, _value(context, "l") + 0.3)
        return (-bound, bound, -bound, bound)

    def paint(self, canvas: Canvas, physics, context) -> None:
        theta = float(np.asarray(physics)[0])
        length = _value(context, "l")
        tip = (length * math.sin(theta), length * math.cos(theta))
        canvas.line((0.0, 0.0), tip, 0.2, ROD_COLOR)
        canvas.circle((0.0, 0.0), 0.05, AXLE_COLOR)


def _hill(position):
    return np.sin(3 * position) * 0.45 + 0.55


class MountainCarRenderer:
    """The hill between the walls ``min_position``/``max_position`` and the flag at ``goal_position``."""

    aspect = 400 / 600

    def world_box(self, context) -> tuple[float, float, float, float]:
        low = min(-1.2, _value(context, "min_position"))
        high = max(0.6, _value(context, "max_position"))
        width = high - low
        return (low, high, -0.1, -0.1 + max(1.2, width * self.aspect))

    def paint(self, canvas: Canvas, physics, context) -> None:
        position = float(np.asarray(physics)[0])
        low, high = _value(context, "min_position"), _value(context, "max_position")
        xs = np.linspace(low, high, 120)
        ys = _hill(xs)
        for x0, y0, x1, y1 in zip(xs[:-1], ys[:-1], xs[1:], ys[1:], strict=True):
            canvas.line((x0, y0), (x1, y1), 0.01, TRACK_COLOR)
        goal = _value(context, "goal_position")
        flag_base = _hill(goal)
        canvas.line((goal, flag_base), (goal, flag_base + 0.15), 0.008, TRACK_COLOR)
        canvas.polygon(
            [(goal, flag_base + 0.15), (goal, flag_base + 0.11), (goal + 0.08, flag_base + 0.13)],
            FLAG_COLOR,
        )
        slope = math.atan(math.cos(3 * position) * 0.45 * 3)
        car_w, car_h = 0.1, 0.05
        base = (position, float(_hill(position)))
        c, s = math.cos(slope), math.sin(slope)
        corners = [(-car_w / 2, 0.01), (car_w / 2, 0.01), (car_w / 2, car_h), (-car_w / 2, car_h)]
        canvas.polygon(
            [(base[0] + cx * c - cy * s, base[1] + cx * s + cy * c) for cx, cy in corners],
            CAR_COLOR,
        )


class AcrobotRenderer:
    """Both links at their lengths, and the goal line the tip must rise above."""

    aspect = 1.0

    def world_box(self, context) -> tuple[float, float, float, float]:
        reach = _value(context, "LINK_LENGTH_1") + _value(context, "LINK_LENGTH_2")
        bound = max(2.2, reach + 0.2)
        return (-bound, bound, -bound, bound)

    def paint(self, canvas: Canvas, physics, context) -> None:
        theta1, theta2 = (float(v) for v in np.asarray(physics)[:2])
        length1, length2 = _value(context, "LINK_LENGTH_1"), _value(context, "LINK_LENGTH_2")
        canvas.line((canvas.x_min, 1.0), (canvas.x_max, 1.0), 0.02, TRACK_COLOR)
        elbow = (length1 * math.sin(theta1), -length1 * math.cos(theta1))
        tip = (
            elbow[0] + length2 * math.sin(theta1 + theta2),
            elbow[1] - length2 * math.cos(theta1 + theta2),
        )
        canvas.line((0.0, 0.0), elbow, 0.1, LINK_COLOR)
        canvas.line(elbow, tip, 0.1, LINK_COLOR)
        canvas.circle((0.0, 0.0), 0.05, FLAG_COLOR)
        canvas.circle(elbow, 0.05, FLAG_COLOR)


RENDERERS = {
    "CartPole": CartPoleRenderer(),
    "Pendulum": PendulumRenderer(),
    "MountainCar": MountainCarRenderer(),
    "MountainCarContinuous": MountainCarRenderer(),
    "Acrobot": AcrobotRenderer(),
}
