"""PointMass (dm_control ``point_mass-easy`` by default): a ball on a plane pushed towards a target.

Its own features, all written into the model in place (no recompile): ``mass`` (``body_mass`` and
inertia of the ball), ``target_x/y`` (the target geom's position, which the reward reads),
``area_size`` (the side of the square arena: joint ranges, walls, floor and the fixed camera scale
with it) and the start. The stock task starts the ball uniformly anywhere in the arena; here the
start is ``(starting_x, starting_y) + start_spread * u`` with ``u`` the stock draw, clipped to the
arena, so the defaults (0, 0, 1) are the stock start and ``start_spread = 0`` a fixed one.
A start or target outside the arena is refused with a clear error.

Features that cannot act here: ``DmcPointMass.left_out``.
"""

from __future__ import annotations

import numpy as np

from contextrl.context.features import ContextBase, ContextError, context_type, feature
from contextrl.envs.dmc import base

WALLS = {"wall_x": (0, 1), "wall_neg_x": (0, 1), "wall_y": (1, 0), "wall_neg_y": (1, 0)}
# wall name -> (axis of its position, axis of its size along the arena's side)


@context_type
class DmcPointMassContext(ContextBase):
    """Context features of the dm_control PointMass; the defaults are the stock model."""

    timestep: float = base.timestep_feature(0.02)
    joint_damping: float = base.joint_damping_feature()
    actuator_strength: float = base.actuator_strength_feature()
    density: float = base.density_feature()
    viscosity: float = base.viscosity_feature()
    wind_x: float = base.wind_feature("x")
    wind_y: float = base.wind_feature("y")
    mass: float = feature(0.3, 0.01, 10.0, unit="kg", doc="mass of the ball")
    starting_x: float = feature(
        0.0, -0.96, 0.96, unit="m", doc="centre of the start region, x", affects=("start_state",)
    )
    starting_y: float = feature(
        0.0, -0.96, 0.96, unit="m", doc="centre of the start region, y", affects=("start_state",)
    )
    start_spread: float = feature(
        1.0,
        0.0,
        1.0,
        doc="scale of the stock uniform start draw (1: anywhere in the arena, 0: fixed start)",
        affects=("start_state",),
    )
    target_x: float = feature(
        0.0, -0.96, 0.96, unit="m", doc="target position, x", affects=("goal",)
    )
    target_y: float = feature(
        0.0, -0.96, 0.96, unit="m", doc="target position, y", affects=("goal",)
    )
    area_size: float = feature(
        0.6, 0.2, 2.0, unit="m", doc="side of the square arena", affects=("dynamics", "start_state")
    )


class DmcPointMass(base.DmcEnv):
    """PointMass on MuJoCo; tasks ``easy`` (default) and ``hard``; 1000 control steps of 20 ms."""

    domain = "point_mass"
    default_task = "easy"
    context_type = DmcPointMassContext
    left_out = {
        "gravity": "the ball slides on two horizontal joints; gravity is perpendicular to both",
        "friction": "the stock model disables contacts",
        "joint_stiffness": "the stock stiffness is 0",
        "wind_z": "vertical, perpendicular to both joints",
        "geom_density": "the ball's mass is set explicitly: use mass",
    }

    def __init__(self, task: str | None = None, **kwargs):
        super().__init__(task, **kwargs)
        model = self._physics.model
        named = self._physics.named.model
        self._ball = model.name2id("pointmass", "body")
        self._stock_area = {
            "jnt_range": model.jnt_range.copy(),
            "ground": named.geom_size["ground"].copy(),
            "walls": {
                name: (named.geom_pos[name].copy(), named.geom_size[name].copy()) for name in WALLS
            },
            "camera": named.cam_pos["fixed"].copy(),
        }

    def _appliers(self) -> set[str]:
        return super()._appliers() | {
            "mass",
            "starting_x",
            "starting_y",
            "start_spread",
            "target_x",
            "target_y",
            "area_size",
        }

    def area_scale(self, area_size: float) -> float:
        """The arena's size relative to the stock one (exactly 1 at the default)."""
        stock_area = self.context_space.features["area_size"].default
        return base.stock_or_value(area_size, stock_area) / stock_area

    def reachable(self, area_size: float) -> float:
        """Half-width of the square the ball's centre can reach (the joint range) for an arena."""
        return float(self._stock_area["jnt_range"][0, 1]) * self.area_scale(area_size)

    def _check_combination(self, values: dict[str, float]) -> None:
        limit = self.reachable(values["area_size"])
        for name in ("starting_x", "starting_y", "target_x", "target_y"):
            if abs(values[name]) > limit:
                raise ContextError(
                    f"{self.name}: {name}={values[name]:.3g} lies outside the arena: with "
                    f"area_size={values['area_size']:.3g} it must be within ±{limit:.3g}"
                )

    def _apply_structure(self, values: dict[str, float]) -> None:
        model, named = self._physics.model, self._physics.named.model
        stock = self._stock_area
        scale = self.area_scale(values["area_size"])
        model.jnt_range[:] = stock["jnt_range"] * scale
        named.geom_size["ground"] = stock["ground"] * np.array([scale, scale, 1.0])
        for name, (position_axis, size_axis) in WALLS.items():
            position, size = stock["walls"][name]
            position, size = position.copy(), size.copy()
            position[position_axis] *= scale
            size[size_axis] *= scale
            named.geom_pos[name] = position
            named.geom_size[name] = size
        named.cam_pos["fixed"] = stock["camera"] * scale
        named.geom_pos["target", "x"] = values["target_x"]
        named.geom_pos["target", "y"] = values["target_y"]
        mass = base.stock_or_value(values["mass"], self._stock_mass[self._ball])
        if self._applied.get("mass") != mass:
            ratio = mass / self._stock_mass[self._ball]
            model.body_mass[self._ball] = mass
            model.body_inertia[self._ball] = self._stock_inertia[self._ball] * ratio
            self._set_const(stock=ratio == 1.0)
            self._applied["mass"] = mass

    def _after_initialize(self, values: dict[str, float]) -> None:
        qpos = self._physics.named.data.qpos
        limit = self.reachable(values["area_size"])
        for joint, centre in (("root_x", values["starting_x"]), ("root_y", values["starting_y"])):
            drawn = float(qpos[joint][0])
            qpos[joint] = np.clip(centre + values["start_spread"] * drawn, -limit, limit)
