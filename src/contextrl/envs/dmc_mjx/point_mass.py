"""PointMass on MJX (dm_control ``point_mass-easy``): a ball on a plane pushed towards a target.

The start, observation and reward are dm_control's, with the reference's own features
(:mod:`contextrl.envs.dmc.point_mass`): the ball's ``mass`` (with its inertia and the derived
constants), the arena's ``area_size`` (the joint ranges; the walls do not collide: the stock model
disables contacts), the target (``target_x/y``, read by the reward) and the start, the stock uniform
draw scaled by ``start_spread`` about (``starting_x``, ``starting_y``) and clipped to the arena.
``hard`` (the actuators' directions drawn per episode, in the tendons' coefficients ``wrap_prm``) is
offered on dm_control only: MJX reads ``wrap_prm`` as a constant of the compiled program.

The reference refuses a start or target outside the arena; a context here is not checked for that
combination (the start is clipped into the arena, a target outside it is out of reach).

It is the family's differentiable task (``contextrl.core.gradient``; why the others are not: ``base``):
without contacts MJX's step is a smooth function of every float feature, checked against central
differences over 20 steps, the medium's included. Two stops: ``timestep`` acts through the
integration, but the number of physics steps per control step is rounded from it, so the return
jumps where that count changes; and at the arena's edge the joint limits (set by ``area_size``) and
the start's clip hold the ball, as a wall would.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from contextrl.envs.dmc import DmcPointMass, DmcPointMassContext
from contextrl.envs.dmc_mjx.base import DmcMjxEnv, tolerance


@dataclasses.dataclass(frozen=True)
class DmcPointMassMjx(DmcMjxEnv):
    """PointMass on MJX; task ``easy``; 1000 control steps of 20 ms."""

    host_class = DmcPointMass
    context_type = DmcPointMassContext
    left_out = DmcPointMass.left_out
    tasks = ("easy",)
    default_task = "easy"
    differentiable = True

    def mass_ratio(self, values):
        ball = self.index("body", "pointmass")
        stock = self.stock.mj_model.body_mass[ball]
        return jnp.ones(self.stock.mj_model.nbody).at[ball].set(values["mass"] / jnp.float32(stock))

    def task_model_changes(self, values):
        scale = values["area_size"] / jnp.float32(self.context_space.features["area_size"].default)
        return {"jnt_range": jnp.asarray(self.stock.model.jnt_range) * scale}

    def start(self, key, model, data, context):
        drawn = self.randomize_joints(key, data, model.jnt_range).qpos
        limit = model.jnt_range[:, 1]
        centre = jnp.stack([context.starting_x, context.starting_y])
        qpos = jnp.clip(centre + context.start_spread * drawn, -limit, limit)
        return data.replace(qpos=qpos), None

    def task_observation(self, data, goal, context):
        return [data.qpos, data.qvel]

    def reward(self, data, goal, action, context):
        model = self.stock.mj_model
        target_geom = self.index("geom", "target")
        target = jnp.stack(
            [context.target_x, context.target_y, jnp.float32(model.geom_pos[target_geom, 2])]
        )
        ball = data.geom_xpos[self.index("geom", "pointmass")]
        size = float(model.geom_size[target_geom, 0])
        near_target = tolerance(jnp.linalg.norm(target - ball), (0.0, size), size)
        control = tolerance(action, margin=1.0, value_at_margin=0.0, sigmoid="quadratic").mean()
        return near_target * (control + 4) / 5
