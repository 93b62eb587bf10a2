"""Pendulum swing-up with an explicit context: gymnasium's ``Pendulum-v1`` at the default context.

``g`` is the gravity that acts (CARL also declares a ``gravity`` that does nothing; here it is an alias of
``g``), and the start angle and velocity are drawn from [−max, max] as in gymnasium.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import ContextBase, context_type, feature
from contextrl.core import scalar
from contextrl.core.env import Env
from contextrl.core.spaces import Box

NOMINAL_TORQUE = 2.0  # the original action bound; the action space stays [−2, 2]


@context_type
class PendulumContext(ContextBase):
    """Context features of Pendulum."""

    g: float = feature(
        10.0,
        0.0,
        100.0,
        unit="m/s²",
        doc="gravitational acceleration, downward",
        affects=("dynamics",),
        aliases=("gravity",),
    )
    m: float = feature(1.0, 0.01, 10.0, unit="kg", doc="mass of the pendulum")
    l: float = feature(1.0, 0.01, 10.0, unit="m", doc="length of the pendulum")  # noqa: E741
    dt: float = feature(0.05, 0.001, 0.5, unit="s", doc="integration time step")
    max_speed: float = feature(
        8.0, 0.5, 50.0, unit="rad/s", doc="angular velocity is clipped to ±max_speed"
    )
    max_torque: float = feature(
        2.0,
        0.1,
        20.0,
        unit="N·m",
        doc="torque at a full action: the action in [−2, 2] is scaled by max_torque / 2",
        affects=("dynamics", "reward"),
    )
    initial_angle_max: float = feature(
        math.pi,
        0.0,
        math.pi,
        unit="rad",
        doc="start angle ~ U(−max, max)",
        affects=("start_state",),
    )
    initial_velocity_max: float = feature(
        1.0, 0.0, 8.0, unit="rad/s", doc="start velocity ~ U(−max, max)", affects=("start_state",)
    )


def angle_normalize(xp, angle):
    """Map an angle to [−π, π)."""
    return ((angle + xp.pi) % (2 * xp.pi)) - xp.pi


def dynamics(xp, state, u, context: PendulumContext):
    """One step under the action ``u`` (a scalar in [−2, 2]): ``(next_state, reward, terminated)``.

    Written against the array namespace ``xp`` (``jax.numpy`` or ``contextrl.core.scalar``).
    """
    theta, theta_dot = state
    u = xp.clip(u, -NOMINAL_TORQUE, NOMINAL_TORQUE)
    torque = u * (context.max_torque / NOMINAL_TORQUE)
    cost = angle_normalize(xp, theta) ** 2 + 0.1 * theta_dot**2 + 0.001 * torque**2
    g, m, length, dt = context.g, context.m, context.l, context.dt
    theta_dot = (
        theta_dot + (3 * g / (2 * length) * xp.sin(theta) + 3.0 / (m * length**2) * torque) * dt
    )
    theta_dot = xp.clip(theta_dot, -context.max_speed, context.max_speed)
    theta = theta + theta_dot * dt
    return xp.stack([theta, theta_dot]), -cost, xp.zeros((), bool)


def observation(xp, state):
    """(cos θ, sin θ, θ̇) of the state (θ, θ̇)."""
    theta, theta_dot = state
    return xp.stack([xp.cos(theta), xp.sin(theta), theta_dot])


@dataclasses.dataclass(frozen=True)
class Pendulum(Env):
    """Swing a pendulum up and hold it; reward −(angle² + 0.1·speed² + 0.001·torque²) (200 steps)."""

    context_type = PendulumContext
    default_max_steps = 200
    differentiable = True

    @property
    def action_space(self) -> Box:
        return Box(np.array([-NOMINAL_TORQUE]), np.array([NOMINAL_TORQUE]))

    @property
    def base_observation_space(self) -> Box:
        speed = PendulumContext.space.features["max_speed"].upper
        return Box(np.array([-1.0, -1.0, -speed]), np.array([1.0, 1.0, speed]))

    def init(self, key, context: PendulumContext) -> jax.Array:
        high = jnp.stack([context.initial_angle_max, context.initial_velocity_max])
        return jax.random.uniform(key, (2,), minval=-high, maxval=high)

    def transition(self, key, state, action, context: PendulumContext):
        return dynamics(jnp, state, jnp.reshape(action, ()), context)

    def observe(self, state, context) -> jax.Array:
        return observation(jnp, state)

    def host_transition(self, state, action: list[float], context):
        """The same step on Python floats (see ``contextrl.core.scalar``)."""
        return dynamics(scalar, state, action[0], context)

    def host_observe(self, state, context):
        return observation(scalar, state)
