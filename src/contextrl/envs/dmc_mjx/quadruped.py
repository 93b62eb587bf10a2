"""Quadruped on MJX (dm_control ``quadruped-walk`` and ``quadruped-run``): a four-legged ant in 3-D.

The start, observation and reward are dm_control's ``Move`` task: a random orientation, placed at the
lowest height (in steps of 1 cm from the floor) where it touches nothing; egocentric joint state,
torso velocity and uprightness, IMU and foot force-torque sensors observed; upright times forward
speed rewarded. ``escape`` and ``fetch`` (terrain, walls and a ball) are offered on dm_control only.

dm_control raises the body 1 cm at a time until no contact is left; here one collision pass at
height 0 gives every contact's distance, and since the floor is a plane, raising the body by ``z``
adds ``z`` to each distance, so the first free height is found at once: the same height, one pass.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from contextrl.envs.dmc import DmcQuadruped, DmcQuadrupedContext
from contextrl.envs.dmc_mjx.base import DmcMjxEnv, random_quaternion, tolerance

SPEEDS = {"walk": 0.5, "run": 5.0}
HEIGHT_STEP = 0.01  # dm_control's step when it searches for a height free of contacts


@dataclasses.dataclass(frozen=True)
class DmcQuadrupedMjx(DmcMjxEnv):
    """Quadruped on MJX; tasks ``walk`` (default) and ``run``; 1000 control steps of 20 ms."""

    host_class = DmcQuadruped
    context_type = DmcQuadrupedContext
    left_out = DmcQuadruped.left_out
    tasks = tuple(SPEEDS)
    default_task = "walk"

    def start(self, key, model, data, context):
        from mujoco import mjx

        root = self.qpos_address("root")
        qpos = data.qpos.at[root : root + 3].set(0.0)
        qpos = qpos.at[root + 3 : root + 7].set(random_quaternion(key))
        placed = mjx.collision(model, mjx.kinematics(model, data.replace(qpos=qpos)))
        lowest = jnp.min(placed._impl.contact.dist)
        steps = jnp.where(lowest > 0, 0.0, jnp.floor(-lowest / HEIGHT_STEP) + 1)
        return data.replace(qpos=qpos.at[root + 2].set(steps * HEIGHT_STEP)), None

    def task_observation(self, data, goal, context):
        import mujoco

        model = self.stock.mj_model
        hinges = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE)
        sensors = mujoco.mjtSensor
        imu = self.sensors_of(data, sensors.mjSENS_GYRO, sensors.mjSENS_ACCELEROMETER)
        force_torque = self.sensors_of(data, sensors.mjSENS_FORCE, sensors.mjSENS_TORQUE)
        return [
            data.qpos[model.jnt_qposadr[hinges]],
            data.qvel[model.jnt_dofadr[hinges]],
            data.act,
            self.sensor(data, "velocimeter"),
            self.upright(data),
            imu,
            jnp.arcsinh(force_torque),
        ]

    def reward(self, data, goal, action, context):
        speed = SPEEDS[self.task]
        upright = tolerance(
            self.upright(data), (1.0, float("inf")), 2.0, sigmoid="linear", value_at_margin=0.0
        )
        move = tolerance(
            self.sensor(data, "velocimeter")[0],
            (speed, float("inf")),
            speed,
            sigmoid="linear",
            value_at_margin=0.5,
        )
        return upright * move

    def upright(self, data):
        return data.xmat[self.index("body", "torso"), 2, 2]

    def sensors_of(self, data, *kinds) -> jnp.ndarray:
        """The readings of every sensor of the given types, in the model's order (as dm_control)."""
        model = self.stock.mj_model
        ids = np.flatnonzero(np.isin(model.sensor_type, kinds))
        entries = np.concatenate(
            [np.arange(model.sensor_adr[i], model.sensor_adr[i] + model.sensor_dim[i]) for i in ids]
        )
        return data.sensordata[entries]
