"""MountainCarContinuous with an explicit context: gymnasium's ``MountainCarContinuous-v0`` at the default.

Gymnasium writes the hill's pull 0.0025 as a constant in this version's equation; here it is the
``gravity`` feature shared with MountainCar. The default goal is gymnasium's 0.45. It is differentiable
as MountainCar is (see there: the speed clip and the left wall stop the gradient through the speed); the
goal's +100 counts in full as :meth:`MountainCarContinuous.termination_bonus`.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import context_type, feature
from contextrl.core import scalar
from contextrl.core.env import Env
from contextrl.core.spaces import Box
from contextrl.envs.classic_control.mountain_car import (
    HillContext,
    goal_margin,
    hill_init,
    hill_observation_space,
    hill_step,
)


@context_type
class MountainCarContinuousContext(HillContext):
    """Context features of MountainCarContinuous."""

    goal_position: float = feature(0.45, -0.5, 1.5, doc="position to reach", affects=("goal",))
    power: float = feature(0.0015, 0.0001, 0.01, doc="velocity change of a full push")


def dynamics(xp, state, action, context: MountainCarContinuousContext):
    """One step under a scalar push ``action`` (clipped to [−1, 1]): ``(next_state, reward, terminated)``.

    Written against the array namespace ``xp`` (``jax.numpy`` or ``contextrl.core.scalar``).
    """
    push = xp.clip(action, -1.0, 1.0) * context.power
    next_state, reached = hill_step(xp, state, push, context)
    reward = xp.where(reached, 100.0, 0.0) - 0.1 * action**2
    return next_state, reward, reached


@dataclasses.dataclass(frozen=True)
class MountainCarContinuous(Env):
    """Drive up the hill with a continuous push in [−1, 1]; +100 at the goal, −0.1·push² per step (999)."""

    context_type = MountainCarContinuousContext
    default_max_steps = 999
    differentiable = True

    @property
    def action_space(self) -> Box:
        return Box(np.array([-1.0]), np.array([1.0]))

    @property
    def base_observation_space(self) -> Box:
        return hill_observation_space(MountainCarContinuousContext)

    def init(self, key, context) -> jax.Array:
        return hill_init(key, context)

    def transition(self, key, state, action, context):
        return dynamics(jnp, state, jnp.reshape(action, ()), context)

    def observe(self, state, context) -> jax.Array:
        return state

    def termination_margin(self, state, context) -> jax.Array:
        return goal_margin(state, context)

    def termination_bonus(self, context) -> float:
        """What the step that reaches the goal earns beyond one that goes on (the +100)."""
        return 100.0

    def host_transition(self, state, action: list[float], context):
        """The same step on Python floats (see ``contextrl.core.scalar``)."""
        return dynamics(scalar, state, action[0], context)

    def host_observe(self, state, context):
        return state
