"""Finger on MJX (dm_control ``finger-spin``, ``finger-turn_easy``, ``finger-turn_hard``).

The start, observation and reward are dm_control's: joint angles drawn at random until the finger
and the spinner touch nothing (a rejection loop, as dm_control's), for the turn tasks a target on the
spinner's circle (held in the state, where dm_control moves the target site); joint angles, the tip
relative to the spinner, velocities and the log of the touch sensors observed.

The geometry features of the reference (limb and spinner lengths, spinner radius) are not offered
here: they change geom sizes and positions and the masses, inertias and collision bounds MuJoCo's
compiler derives from them, which the reference gets by recompiling the edited XML.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import ContextBase, context_type
from contextrl.envs.dmc import DmcFinger, DmcFingerContext
from contextrl.envs.dmc.finger import GEOMETRY
from contextrl.envs.dmc_mjx.base import DmcMjxEnv, contacts_touching

SPIN_VELOCITY = 15.0
TARGET_RADII = {"turn_easy": 0.07, "turn_hard": 0.03}
MAX_ATTEMPTS = 1000  # dm_control's, for a start free of contacts
GEOMETRY_REASON = (
    "changes geom sizes and the masses, inertias and collision bounds MuJoCo's compiler derives "
    "from them; offered on the dm_control backend, which recompiles the model"
)


def _mjx_context_class() -> type:
    """The reference's context features without the geometry ones."""
    fields = {
        name: field
        for name, field in DmcFingerContext.__dataclass_fields__.items()
        if name not in GEOMETRY
    }
    namespace = {
        "__annotations__": {name: float for name in fields},
        "__doc__": "Context features of the dm_control Finger on MJX; the defaults are the stock model.",
        "__module__": __name__,
        "__qualname__": "DmcFingerMjxContext",
        **{
            name: dataclasses.field(default=field.default, metadata=field.metadata)
            for name, field in fields.items()
        },
    }
    return context_type(type("DmcFingerMjxContext", (ContextBase,), namespace))


DmcFingerMjxContext = _mjx_context_class()


@dataclasses.dataclass(frozen=True)
class DmcFingerMjx(DmcMjxEnv):
    """Finger on MJX; tasks ``spin`` (default), ``turn_easy``, ``turn_hard``; 20 ms control."""

    host_class = DmcFinger
    context_type = DmcFingerMjxContext
    left_out = {**DmcFinger.left_out, **{name: GEOMETRY_REASON for name in GEOMETRY}}
    tasks = ("spin", *TARGET_RADII)
    default_task = "spin"

    def start(self, key, model, data, context):
        from mujoco import mjx

        angle_key, joints_key = jax.random.split(key)
        goal = None
        if self.task != "spin":
            hinge_x, _, hinge_z = self.hinge_anchor
            radius = float(self.stock.mj_model.geom_size[self.index("geom", "cap1")].sum())
            angle = jax.random.uniform(angle_key, (), minval=-np.pi, maxval=np.pi)
            goal = jnp.stack(
                [hinge_x + radius * jnp.sin(angle), 0.0, hinge_z + radius * jnp.cos(angle)]
            )

        def draw(attempt):
            drawn = self.randomize_joints(
                jax.random.fold_in(joints_key, attempt), data, model.jnt_range
            )
            touching = contacts_touching(mjx.collision(model, mjx.kinematics(model, drawn)))
            return drawn, touching

        def retry(carry):
            attempt, _, _ = carry
            return (attempt + 1, *draw(attempt + 1))

        def keep_trying(carry):
            attempt, _, touching = carry
            return touching & (attempt < MAX_ATTEMPTS - 1)

        _, drawn, _ = jax.lax.while_loop(keep_trying, retry, (0, *draw(0)))
        return drawn, goal

    @property
    def hinge_anchor(self) -> np.ndarray:
        """Where the spinner's hinge is in the world (fixed: the spinner body does not move)."""
        host = self.stock.mj_model
        body = host.jnt_bodyid[self.index("joint", "hinge")]
        return np.asarray(host.body_pos[body]) + np.asarray(
            host.jnt_pos[self.index("joint", "hinge")]
        )

    def tip_position(self, data):
        return self.sensor(data, "tip")[::2] - self.sensor(data, "spinner")[::2]

    def task_observation(self, data, goal, context):
        parts = [
            self.sensor(data, "proximal"),
            self.sensor(data, "distal"),
            self.tip_position(data),
            self.sensor(data, "proximal_velocity"),
            self.sensor(data, "distal_velocity"),
            self.sensor(data, "hinge_velocity"),
            jnp.log1p(self.sensor(data, "touchtop")),
            jnp.log1p(self.sensor(data, "touchbottom")),
        ]
        if self.task == "spin":
            return parts
        target = goal[::2] - self.sensor(data, "spinner")[::2]
        return [*parts, target, self.distance_to_target(data, goal)]

    def distance_to_target(self, data, goal):
        target = goal[::2] - self.sensor(data, "spinner")[::2]
        return jnp.linalg.norm(target - self.tip_position(data)) - TARGET_RADII[self.task]

    def reward(self, data, goal, action, context):
        if self.task == "spin":
            return (self.sensor(data, "hinge_velocity")[0] <= -SPIN_VELOCITY).astype(jnp.float32)
        return (self.distance_to_target(data, goal) <= 0).astype(jnp.float32)
