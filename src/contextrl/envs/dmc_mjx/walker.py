"""Walker on MJX (dm_control ``walker-stand``, ``walker-walk``, ``walker-run``): a planar biped.

The start, observation and reward are dm_control's ``PlanarWalker``: every hinge and limited slide
joint drawn at random (the walker falls to the floor), body orientations, torso height and joint
velocities observed, a reward for standing tall and upright times one for the centre of mass moving
forward at the task's speed. The context is the reference's (:class:`~contextrl.envs.dmc.DmcWalkerContext`).
"""

from __future__ import annotations

import dataclasses

from contextrl.envs.dmc import DmcWalker, DmcWalkerContext
from contextrl.envs.dmc_mjx.base import DmcMjxEnv, tolerance

STAND_HEIGHT = 1.2
SPEEDS = {"stand": 0.0, "walk": 1.0, "run": 8.0}


@dataclasses.dataclass(frozen=True)
class DmcWalkerMjx(DmcMjxEnv):
    """Walker on MJX; tasks ``stand``, ``walk`` (default), ``run``; 1000 control steps of 25 ms."""

    host_class = DmcWalker
    context_type = DmcWalkerContext
    left_out = DmcWalker.left_out
    tasks = tuple(SPEEDS)
    default_task = "walk"

    def start(self, key, model, data, context):
        return self.randomize_joints(key, data, model.jnt_range), None

    def task_observation(self, data, goal, context):
        torso = self.index("body", "torso")
        return [data.xmat[1:, 0, ::2], data.xpos[torso, 2], data.qvel]

    def reward(self, data, goal, action, context):
        torso = self.index("body", "torso")
        standing = tolerance(data.xpos[torso, 2], (STAND_HEIGHT, float("inf")), STAND_HEIGHT / 2)
        upright = (1 + data.xmat[torso, 2, 2]) / 2
        stand_reward = (3 * standing + upright) / 4
        speed = SPEEDS[self.task]
        if speed == 0:
            return stand_reward
        velocity = self.sensor(data, "torso_subtreelinvel")[0]
        move_reward = tolerance(
            velocity, (speed, float("inf")), speed / 2, sigmoid="linear", value_at_margin=0.5
        )
        return stand_reward * (5 * move_reward + 1) / 6
