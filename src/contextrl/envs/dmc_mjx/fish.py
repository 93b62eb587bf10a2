"""Fish on MJX (dm_control ``fish-upright`` and ``fish-swim``): a fish in a dense medium.

The start, observation and reward are dm_control's: a random orientation and fin angles within
±0.2 rad, for ``swim`` a target drawn in the tank (held in the state, where dm_control moves the
target geom); joint angles, uprightness, the target seen from the mouth and the velocities observed.

MJX has no collision function for the pair of the stock model's torso box and tail ellipsoid, so the
model is loaded with every geom's ``contype`` and ``conaffinity`` at 0. dm_control's Fish disables
all constraints (``<flag constraint="disable"/>``), contacts included, so the physics is unchanged.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from contextrl.envs.dmc import DmcFish, DmcFishContext
from contextrl.envs.dmc_mjx.base import DmcMjxEnv, random_quaternion, tolerance

JOINTS = (
    "tail1",
    "tail_twist",
    "tail2",
    "finright_roll",
    "finright_pitch",
    "finleft_roll",
    "finleft_pitch",
)


@dataclasses.dataclass(frozen=True)
class DmcFishMjx(DmcMjxEnv):
    """Fish on MJX; tasks ``upright`` and ``swim`` (default); 1000 control steps of 40 ms."""

    host_class = DmcFish
    context_type = DmcFishContext
    left_out = DmcFish.left_out
    tasks = ("upright", "swim")
    default_task = "swim"
    contacts = False

    def start(self, key, model, data, context):
        turn, fins, x, y, z = jax.random.split(key, 5)
        root = self.qpos_address("root")
        qpos = data.qpos.at[root + 3 : root + 7].set(random_quaternion(turn))
        angles = jax.random.uniform(fins, (len(JOINTS),), minval=-0.2, maxval=0.2)
        qpos = qpos.at[jnp.asarray(self.joint_addresses)].set(angles)
        target = jnp.stack(
            [
                jax.random.uniform(x, (), minval=-0.4, maxval=0.4),
                jax.random.uniform(y, (), minval=-0.4, maxval=0.4),
                jax.random.uniform(z, (), minval=0.1, maxval=0.3),
            ]
        )
        return data.replace(qpos=qpos), target if self.task == "swim" else None

    @property
    def joint_addresses(self) -> list[int]:
        return [self.qpos_address(joint) for joint in JOINTS]

    def task_observation(self, data, goal, context):
        angles = data.qpos[jnp.asarray(self.joint_addresses)]
        if self.task == "upright":
            return [angles, self.upright(data), data.qvel]
        return [angles, self.upright(data), self.mouth_to_target(data, goal), data.qvel]

    def reward(self, data, goal, action, context):
        if self.task == "upright":
            return tolerance(self.upright(data), (1.0, 1.0), 1.0)
        sizes = self.stock.mj_model.geom_size
        radii = float(
            sizes[self.index("geom", "mouth"), 0] + sizes[self.index("geom", "target"), 0]
        )
        distance = jnp.linalg.norm(self.mouth_to_target(data, goal))
        in_target = tolerance(distance, (0.0, radii), 2 * radii)
        return (7 * in_target + 0.5 * (self.upright(data) + 1)) / 8

    def upright(self, data):
        return data.xmat[self.index("body", "torso"), 2, 2]

    def mouth_to_target(self, data, target):
        """The target's position relative to the mouth, in the mouth's frame."""
        mouth = self.index("geom", "mouth")
        return (target - data.geom_xpos[mouth]) @ data.geom_xmat[mouth]
