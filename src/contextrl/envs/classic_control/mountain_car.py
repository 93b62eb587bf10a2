"""MountainCar with an explicit context: gymnasium's ``MountainCar-v0`` at the default context.

The default goal is gymnasium's 0.5 (CARL swaps the goals of the discrete and continuous versions).
The car's physics are shared with MountainCarContinuous, which differs only in how it is pushed.

Both cars are differentiable in their float features (``contextrl.core.gradient``) almost everywhere,
with two stops that zero the gradient through the speed: a speed clipped at ``max_speed`` (which acts
only through such steps), and the left wall, where the position is clipped to ``min_position`` and the
speed reset to 0. The wall is also a jump: in a context where the car just reaches it, it is stopped one
step sooner or later, so the return is discontinuous there and its gradient holds only between such
contexts. Reaching the goal ends the episode; :func:`goal_margin` measures how far from it the car is.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import Coherence, ContextBase, context_type, feature
from contextrl.core import scalar
from contextrl.core.env import Env
from contextrl.core.spaces import Box, Discrete


@dataclasses.dataclass(frozen=True)
class HillContext(ContextBase):
    """The features both mountain cars share; each car adds how it is pushed and its own goal default."""

    gravity: float = feature(0.0025, 0.0001, 0.01, doc="pull of the hill's slope per step")
    max_speed: float = feature(0.07, 0.01, 0.5, doc="speed is clipped to ±max_speed")
    min_position: float = feature(-1.2, -3.0, -0.7, doc="left wall (the car stops there)")
    max_position: float = feature(0.6, 0.1, 3.0, doc="right end of the track")
    goal_position: float = feature(0.5, -0.5, 1.5, doc="position to reach", affects=("goal",))
    goal_velocity: float = feature(
        0.0, -0.07, 0.07, doc="minimum velocity at the goal", affects=("goal",)
    )
    min_position_start: float = feature(
        -0.6, -1.2, 0.5, doc="start position ~ U(min, max)", affects=("start_state",)
    )
    max_position_start: float = feature(
        -0.4, -1.2, 0.5, doc="start position ~ U(min, max)", affects=("start_state",)
    )
    min_velocity_start: float = feature(
        0.0, -0.07, 0.07, doc="start velocity ~ U(min, max)", affects=("start_state",)
    )
    max_velocity_start: float = feature(
        0.0, -0.07, 0.07, doc="start velocity ~ U(min, max)", affects=("start_state",)
    )

    coherence: ClassVar[tuple[Coherence, ...]] = (
        Coherence(
            ("goal_position", "max_position"),
            lambda goal, end: goal <= end,
            "goal_position <= max_position",
            "a goal beyond the end of the track can never be reached",
        ),
        Coherence(
            ("min_position", "min_position_start"),
            lambda wall, start: wall <= start,
            "min_position <= min_position_start",
            "the car would start left of the wall",
        ),
        Coherence(
            ("max_position_start", "max_position"),
            lambda start, end: start <= end,
            "max_position_start <= max_position",
            "the car would start beyond the end of the track",
        ),
    )


def hill_init(key, context) -> jax.Array:
    """Start position and velocity, each uniform between its two start features."""
    low = jnp.stack([context.min_position_start, context.min_velocity_start])
    high = jnp.stack([context.max_position_start, context.max_velocity_start])
    return low + jax.random.uniform(key, (2,)) * (high - low)


def hill_step(xp, state, push, context) -> tuple[jax.Array, jax.Array]:
    """Advance the car by one step under a push; returns (next state, reached the goal).

    Written against the array namespace ``xp`` (``jax.numpy`` or ``contextrl.core.scalar``).
    """
    position, velocity = state
    velocity = velocity + push - context.gravity * xp.cos(3 * position)
    velocity = xp.clip(velocity, -context.max_speed, context.max_speed)
    position = xp.clip(position + velocity, context.min_position, context.max_position)
    velocity = xp.where((position <= context.min_position) & (velocity < 0), 0.0, velocity)
    reached = (position >= context.goal_position) & (velocity >= context.goal_velocity)
    return xp.stack([position, velocity]), reached


def goal_margin(state, context) -> jax.Array:
    """How far the car is from the goal: the larger of its shortfall in position and in velocity
    (negative once both are reached)."""
    position, velocity = state[0], state[1]
    return jnp.maximum(context.goal_position - position, context.goal_velocity - velocity)


def hill_observation_space(context_class) -> Box:
    features = context_class.space.features
    low = [features["min_position"].lower, -features["max_speed"].upper]
    high = [features["max_position"].upper, features["max_speed"].upper]
    return Box(np.array(low), np.array(high))


@context_type
class MountainCarContext(HillContext):
    """Context features of MountainCar."""

    force: float = feature(0.001, 0.0001, 0.01, doc="velocity change of one push")


def dynamics(xp, state, action, context: MountainCarContext):
    """One step under a push left (0), none (1) or right (2): ``(next_state, reward, terminated)``."""
    push = (action - 1) * context.force
    next_state, reached = hill_step(xp, state, push, context)
    return next_state, xp.float32(-1.0), reached


@dataclasses.dataclass(frozen=True)
class MountainCar(Env):
    """Drive an underpowered car up a hill: push left, none or right; −1 per step (200 steps)."""

    context_type = MountainCarContext
    default_max_steps = 200
    differentiable = True

    @property
    def action_space(self) -> Discrete:
        return Discrete(3)

    @property
    def base_observation_space(self) -> Box:
        return hill_observation_space(MountainCarContext)

    def init(self, key, context) -> jax.Array:
        return hill_init(key, context)

    def transition(self, key, state, action, context):
        return dynamics(jnp, state, action, context)

    def observe(self, state, context) -> jax.Array:
        return state

    def termination_margin(self, state, context) -> jax.Array:
        return goal_margin(state, context)

    def host_transition(self, state, action: int, context):
        """The same step on Python floats (see ``contextrl.core.scalar``)."""
        return dynamics(scalar, state, action, context)

    def host_observe(self, state, context):
        return state
