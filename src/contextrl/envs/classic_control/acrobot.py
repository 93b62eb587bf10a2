"""Acrobot with an explicit context: gymnasium's ``Acrobot-v1`` ("book" dynamics) at the default context.

In the original equations the second link's length never enters the dynamics (its centre of mass does);
here it sets the goal height together with the first link's length, so it acts (CARL's does nothing).

The dynamics are differentiable in every float feature (``contextrl.core.gradient``): the Runge–Kutta
step is smooth, the angle wrap shifts by whole turns (the physics and observation are periodic), and the
torque noise is ``U(−max, max)`` of a fixed key, linear in ``torque_noise_max``. A speed clipped at
``MAX_VEL_1``/``MAX_VEL_2`` has no derivative in the state, so a clipped step zeros the gradient through
that joint's speed; the two ``MAX_VEL`` features act only through such steps. Reaching the goal earns 0
where a step that goes on earns −1: the rollout counts that 1 as :meth:`Acrobot.termination_bonus`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import Coherence, ContextBase, context_type, feature
from contextrl.core.env import Env
from contextrl.core.spaces import Box, Discrete

DT = 0.2
GRAVITY = 9.8
GOAL_HEIGHT = 1.0


@context_type
class AcrobotContext(ContextBase):
    """Context features of Acrobot (gymnasium's attribute names; the paper's lowercase ones as aliases)."""

    LINK_LENGTH_1: float = feature(
        1.0,
        0.1,
        10.0,
        unit="m",
        doc="length of the first link (dynamics and goal height)",
        affects=("dynamics", "goal"),
        aliases=("link_length_1",),
    )
    LINK_LENGTH_2: float = feature(
        1.0,
        0.1,
        10.0,
        unit="m",
        doc="length of the second link (goal height)",
        affects=("goal",),
        aliases=("link_length_2",),
    )
    LINK_MASS_1: float = feature(
        1.0, 0.1, 10.0, unit="kg", doc="mass of the first link", aliases=("link_mass_1",)
    )
    LINK_MASS_2: float = feature(
        1.0, 0.1, 10.0, unit="kg", doc="mass of the second link", aliases=("link_mass_2",)
    )
    LINK_COM_POS_1: float = feature(
        0.5, 0.0, 1.0, unit="m", doc="centre of mass of the first link", aliases=("link_com_1",)
    )
    LINK_COM_POS_2: float = feature(
        0.5, 0.0, 1.0, unit="m", doc="centre of mass of the second link", aliases=("link_com_2",)
    )
    LINK_MOI: float = feature(
        1.0, 0.1, 10.0, unit="kg·m²", doc="moment of inertia of both links", aliases=("link_moi",)
    )
    MAX_VEL_1: float = feature(
        4 * math.pi,
        0.4 * math.pi,
        40 * math.pi,
        unit="rad/s",
        doc="first joint's speed is clipped to ±MAX_VEL_1",
        aliases=("max_velocity_1",),
    )
    MAX_VEL_2: float = feature(
        9 * math.pi,
        0.9 * math.pi,
        90 * math.pi,
        unit="rad/s",
        doc="second joint's speed is clipped to ±MAX_VEL_2",
        aliases=("max_velocity_2",),
    )
    torque_noise_max: float = feature(
        0.0, 0.0, 1.0, unit="N·m", doc="uniform noise U(−max, max) added to each torque"
    )
    INITIAL_ANGLE_LOWER: float = feature(
        -0.1,
        -math.pi,
        0.0,
        unit="rad",
        doc="start angles ~ U(lower, upper)",
        affects=("start_state",),
        aliases=("initial_angle_lower",),
    )
    INITIAL_ANGLE_UPPER: float = feature(
        0.1,
        0.0,
        math.pi,
        unit="rad",
        doc="start angles ~ U(lower, upper)",
        affects=("start_state",),
        aliases=("initial_angle_upper",),
    )
    INITIAL_VELOCITY_LOWER: float = feature(
        -0.1,
        -1.0,
        0.0,
        unit="rad/s",
        doc="start velocities ~ U(lower, upper)",
        affects=("start_state",),
        aliases=("initial_velocity_lower",),
    )
    INITIAL_VELOCITY_UPPER: float = feature(
        0.1,
        0.0,
        1.0,
        unit="rad/s",
        doc="start velocities ~ U(lower, upper)",
        affects=("start_state",),
        aliases=("initial_velocity_upper",),
    )

    coherence: ClassVar[tuple[Coherence, ...]] = (
        Coherence(
            ("LINK_LENGTH_1", "LINK_LENGTH_2"),
            lambda first, second: first + second > GOAL_HEIGHT,
            f"LINK_LENGTH_1 + LINK_LENGTH_2 > {GOAL_HEIGHT:g} (the goal height)",
            "shorter links can never lift the tip to the goal",
        ),
    )


def wrap(x, low, high, xp=jnp):
    """Shift x by whole periods into [low, high], exactly as gymnasium's loop does."""
    period = high - low
    above = x - period * xp.ceil((x - high) / period)
    below = x + period * xp.ceil((low - x) / period)
    return xp.where(x > high, above, xp.where(x < low, below, x))


def derivatives(xp, s, torque, c: AcrobotContext) -> jax.Array:
    """Time derivative of (θ1, θ2, θ̇1, θ̇2) under a torque on the second joint (the book's equations)."""
    theta1, theta2, dtheta1, dtheta2 = s
    m1, m2, l1 = c.LINK_MASS_1, c.LINK_MASS_2, c.LINK_LENGTH_1
    lc1, lc2, inertia = c.LINK_COM_POS_1, c.LINK_COM_POS_2, c.LINK_MOI
    d1 = m1 * lc1**2 + m2 * (l1**2 + lc2**2 + 2 * l1 * lc2 * xp.cos(theta2)) + 2 * inertia
    d2 = m2 * (lc2**2 + l1 * lc2 * xp.cos(theta2)) + inertia
    phi2 = m2 * lc2 * GRAVITY * xp.cos(theta1 + theta2 - xp.pi / 2.0)
    phi1 = (
        -m2 * l1 * lc2 * dtheta2**2 * xp.sin(theta2)
        - 2 * m2 * l1 * lc2 * dtheta2 * dtheta1 * xp.sin(theta2)
        + (m1 * lc1 + m2 * l1) * GRAVITY * xp.cos(theta1 - xp.pi / 2)
        + phi2
    )
    ddtheta2 = (torque + d2 / d1 * phi1 - m2 * l1 * lc2 * dtheta1**2 * xp.sin(theta2) - phi2) / (
        m2 * lc2**2 + inertia - d2**2 / d1
    )
    ddtheta1 = -(d2 * ddtheta2 + phi1) / d1
    return xp.stack([dtheta1, dtheta2, ddtheta1, ddtheta2])


def rk4(xp, s, torque, c: AcrobotContext, dt: float) -> jax.Array:
    """One classical Runge–Kutta step of length dt."""
    k1 = derivatives(xp, s, torque, c)
    k2 = derivatives(xp, s + dt / 2 * k1, torque, c)
    k3 = derivatives(xp, s + dt / 2 * k2, torque, c)
    k4 = derivatives(xp, s + dt * k3, torque, c)
    return s + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def dynamics(xp, state, torque, context: AcrobotContext):
    """One step under ``torque`` (action − 1, plus any noise): ``(next_state, reward, terminated)``.

    Written against the array namespace ``xp`` (``jax.numpy`` or ``contextrl.core.scalar``); on the
    host ``state`` is a ``scalar.Vector``, whose arithmetic is elementwise like an array's.
    """
    s = rk4(xp, state, torque, context, DT)
    s = xp.stack(
        [
            wrap(s[0], -xp.pi, xp.pi, xp),
            wrap(s[1], -xp.pi, xp.pi, xp),
            xp.clip(s[2], -context.MAX_VEL_1, context.MAX_VEL_1),
            xp.clip(s[3], -context.MAX_VEL_2, context.MAX_VEL_2),
        ]
    )
    height = -context.LINK_LENGTH_1 * xp.cos(s[0]) - context.LINK_LENGTH_2 * xp.cos(s[0] + s[1])
    terminated = height > GOAL_HEIGHT
    return s, xp.where(terminated, 0.0, -1.0), terminated


def observation(xp, state):
    """(cos θ1, sin θ1, cos θ2, sin θ2, θ̇1, θ̇2) of the state (θ1, θ2, θ̇1, θ̇2)."""
    theta1, theta2, dtheta1, dtheta2 = state
    return xp.stack(
        [xp.cos(theta1), xp.sin(theta1), xp.cos(theta2), xp.sin(theta2), dtheta1, dtheta2]
    )


@dataclasses.dataclass(frozen=True)
class Acrobot(Env):
    """Swing the tip of a two-link arm above a line by torquing the middle joint; −1 per step (500)."""

    context_type = AcrobotContext
    default_max_steps = 500
    stochastic_transition = True
    differentiable = True

    @property
    def action_space(self) -> Discrete:
        return Discrete(3)

    @property
    def base_observation_space(self) -> Box:
        features = AcrobotContext.space.features
        high = np.array(
            [1.0, 1.0, 1.0, 1.0, features["MAX_VEL_1"].upper, features["MAX_VEL_2"].upper]
        )
        return Box(-high, high)

    def init(self, key, context: AcrobotContext) -> jax.Array:
        low = jnp.stack([context.INITIAL_ANGLE_LOWER] * 2 + [context.INITIAL_VELOCITY_LOWER] * 2)
        high = jnp.stack([context.INITIAL_ANGLE_UPPER] * 2 + [context.INITIAL_VELOCITY_UPPER] * 2)
        return low + jax.random.uniform(key, (4,)) * (high - low)

    def transition(self, key, state, action, context: AcrobotContext):
        noise = context.torque_noise_max
        torque = (
            jnp.asarray(action, jnp.float32)
            - 1.0
            + jax.random.uniform(key, (), minval=-noise, maxval=noise)
        )
        return dynamics(jnp, state, torque, context)

    def observe(self, state, context) -> jax.Array:
        return observation(jnp, state)

    def termination_margin(self, state, context) -> jax.Array:
        """How far the tip is below the goal height (negative above it)."""
        theta1, theta2 = state[0], state[1]
        height = -context.LINK_LENGTH_1 * jnp.cos(theta1) - context.LINK_LENGTH_2 * jnp.cos(
            theta1 + theta2
        )
        return GOAL_HEIGHT - height

    def termination_bonus(self, context) -> float:
        """What the step that reaches the goal earns beyond one that goes on (0 against −1)."""
        return 1.0
