"""CartPole with an explicit context: gymnasium's ``CartPole-v1`` at the default context.

Total mass and pole mass-length are derived inside the transition from ``masscart``, ``masspole`` and
``length``, so every one of them acts (CARL caches the derived values at construction).
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
from contextrl.core.spaces import Box, Discrete

X_THRESHOLD = 2.4
THETA_THRESHOLD = 12 * 2 * math.pi / 360
FLOAT32_MAX = float(np.finfo(np.float32).max)


@context_type
class CartPoleContext(ContextBase):
    """Context features of CartPole."""

    gravity: float = feature(
        9.8, 0.1, 100.0, unit="m/s²", doc="gravitational acceleration, downward"
    )
    masscart: float = feature(1.0, 0.1, 10.0, unit="kg", doc="mass of the cart")
    masspole: float = feature(0.1, 0.01, 1.0, unit="kg", doc="mass of the pole")
    length: float = feature(
        0.5, 0.05, 5.0, unit="m", doc="half the pole's length", aliases=("pole_length",)
    )
    force_mag: float = feature(
        10.0, 1.0, 100.0, unit="N", doc="force of one push", aliases=("force_magnifier",)
    )
    tau: float = feature(
        0.02, 0.002, 0.2, unit="s", doc="Euler time step", aliases=("update_interval",)
    )
    initial_state_lower: float = feature(
        -0.05,
        -0.2,
        0.0,
        doc="lower end of the uniform start state (all four variables)",
        affects=("start_state",),
    )
    initial_state_upper: float = feature(
        0.05,
        0.0,
        0.2,
        doc="upper end of the uniform start state (all four variables)",
        affects=("start_state",),
    )


def dynamics(xp, state, action, context: CartPoleContext):
    """One Euler step under a push left (0) or right (1): ``(next_state, reward, terminated)``.

    Written against the array namespace ``xp`` (``jax.numpy`` or ``contextrl.core.scalar``).
    """
    x, x_dot, theta, theta_dot = state
    total_mass = context.masspole + context.masscart
    polemass_length = context.masspole * context.length
    force = xp.where(action == 1, context.force_mag, -context.force_mag)
    cos_theta, sin_theta = xp.cos(theta), xp.sin(theta)
    temp = (force + polemass_length * theta_dot**2 * sin_theta) / total_mass
    theta_acc = (context.gravity * sin_theta - cos_theta * temp) / (
        context.length * (4.0 / 3.0 - context.masspole * cos_theta**2 / total_mass)
    )
    x_acc = temp - polemass_length * theta_acc * cos_theta / total_mass
    tau = context.tau
    next_state = xp.stack(
        [
            x + tau * x_dot,
            x_dot + tau * x_acc,
            theta + tau * theta_dot,
            theta_dot + tau * theta_acc,
        ]
    )
    x, theta = next_state[0], next_state[2]
    terminated = (xp.abs(x) > X_THRESHOLD) | (xp.abs(theta) > THETA_THRESHOLD)
    return next_state, xp.float32(1.0), terminated


@dataclasses.dataclass(frozen=True)
class CartPole(Env):
    """Balance a pole on a cart by pushing left or right; +1 per step until it falls (500 steps)."""

    context_type = CartPoleContext
    default_max_steps = 500
    differentiable = True

    @property
    def action_space(self) -> Discrete:
        return Discrete(2)

    @property
    def base_observation_space(self) -> Box:
        # The original bounds x and theta by twice the thresholds; extreme contexts overshoot them in
        # the terminating step, so every variable is bounded by float32's range instead.
        return Box(np.full(4, -FLOAT32_MAX), np.full(4, FLOAT32_MAX))

    def init(self, key, context: CartPoleContext) -> jax.Array:
        return jax.random.uniform(
            key, (4,), minval=context.initial_state_lower, maxval=context.initial_state_upper
        )

    def transition(self, key, state, action, context: CartPoleContext):
        return dynamics(jnp, state, action, context)

    def observe(self, state, context) -> jax.Array:
        return state

    def termination_margin(self, state, context) -> jax.Array:
        """The smaller of the cart's and the pole's distance to their limits, as fractions of them."""
        x, theta = state[0], state[2]
        return jnp.minimum(1 - jnp.abs(x) / X_THRESHOLD, 1 - jnp.abs(theta) / THETA_THRESHOLD)

    def host_transition(self, state, action: int, context):
        """The same step on Python floats (see ``contextrl.core.scalar``)."""
        return dynamics(scalar, state, action, context)

    def host_observe(self, state, context):
        return state
