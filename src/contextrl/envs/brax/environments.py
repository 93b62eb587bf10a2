"""The ten Brax tasks, each a declaration over ``BraxEnv``: its brax name, observation size, the link
masses CARL exposes (stock values of brax's models) and what its model has (contacts, joint springs, a
goal variant). Everything else (features, per-copy system, reset and step) is shared in ``base.py``."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import feature
from contextrl.envs.brax.base import COMPASS, PLANAR_COMPASS, BraxEnv

HUMANOID_MASSES = {
    "mass_torso": ("torso", 8.907462),
    "mass_lwaist": ("lwaist", 2.2619467),
    "mass_pelvis": ("pelvis", 6.6161942),
    "mass_right_thigh": ("right_thigh", 4.751751),
    "mass_right_shin": ("right_shin", 4.522842),
    "mass_left_thigh": ("left_thigh", 4.751751),
    "mass_left_shin": ("left_shin", 4.522842),
    "mass_right_upper_arm": ("right_upper_arm", 1.6610805),
    "mass_right_lower_arm": ("right_lower_arm", 1.2295402),
    "mass_left_upper_arm": ("left_upper_arm", 1.6610805),
    "mass_left_lower_arm": ("left_lower_arm", 1.2295402),
}


@dataclasses.dataclass(frozen=True)
class Ant(BraxEnv):
    """A four-legged ant runs forward (+x); reward forward speed + alive bonus − control cost."""

    brax_name = "ant"
    observation_size = 27
    masses = {"mass_torso": ("torso", 0.48388025)}
    goal_directions = COMPASS


@dataclasses.dataclass(frozen=True)
class HalfCheetah(BraxEnv):
    """A planar cheetah runs forward; reward forward speed − control cost (never terminates)."""

    brax_name = "halfcheetah"
    observation_size = 17
    masses = {
        "mass_torso": ("torso", 6.2502093),
        "mass_bthigh": ("bthigh", 1.5435146),
        "mass_bshin": ("bshin", 1.5874476),
        "mass_bfoot": ("bfoot", 1.0953975),
        "mass_fthigh": ("fthigh", 1.4380753),
        "mass_fshin": ("fshin", 1.2008368),
        "mass_ffoot": ("ffoot", 0.8845188),
    }
    stock_angular_damping = -0.01
    has_joint_stiffness = True
    goal_directions = PLANAR_COMPASS


@dataclasses.dataclass(frozen=True)
class Hopper(BraxEnv):
    """A planar one-legged hopper hops forward without falling; ends when it falls."""

    brax_name = "hopper"
    observation_size = 11
    masses = {
        "mass_torso": ("torso", 3.6651914),
        "mass_thigh": ("thigh", 4.0578904),
        "mass_leg": ("leg", 2.7813568),
        "mass_foot": ("foot", 5.3155746),
    }
    stock_angular_damping = -0.05
    goal_directions = PLANAR_COMPASS


@dataclasses.dataclass(frozen=True)
class Walker2d(BraxEnv):
    """A planar biped walks forward without falling; ends when it falls."""

    brax_name = "walker2d"
    observation_size = 17
    masses = {
        "mass_torso": ("torso", 3.6651914),
        "mass_thigh": ("thigh", 4.0578904),
        "mass_leg": ("leg", 2.7813568),
        "mass_foot": ("foot", 3.1667254),
        "mass_thigh_left": ("thigh_left", 4.0578904),
        "mass_leg_left": ("leg_left", 2.7813568),
        "mass_foot_left": ("foot_left", 3.1667254),
    }
    stock_angular_damping = -0.05
    goal_directions = PLANAR_COMPASS


@dataclasses.dataclass(frozen=True)
class Humanoid(BraxEnv):
    """A 3D humanoid runs forward without falling; ends when the torso drops out of [1, 2] m."""

    brax_name = "humanoid"
    observation_size = 244
    masses = HUMANOID_MASSES
    stock_angular_damping = -0.05
    has_joint_stiffness = True
    max_joint_damping = 2.0  # 5.5× the stock damping already diverges (the hands are light)
    goal_directions = COMPASS


@dataclasses.dataclass(frozen=True)
class HumanoidStandup(BraxEnv):
    """A humanoid lying down stands up; reward the torso's height (never terminates)."""

    brax_name = "humanoidstandup"
    observation_size = 244
    masses = HUMANOID_MASSES
    stock_angular_damping = -0.05
    has_joint_stiffness = True
    max_joint_damping = 2.0  # 5.5× the stock damping already diverges (the hands are light)


@dataclasses.dataclass(frozen=True)
class InvertedPendulum(BraxEnv):
    """Balance a pole on a cart; reward 1 per step, ends when the pole leans over 0.2 rad."""

    brax_name = "inverted_pendulum"
    observation_size = 4
    masses = {"mass_cart": ("cart", 10.471975), "mass_pole": ("pole", 5.0185914)}
    has_friction = False


@dataclasses.dataclass(frozen=True)
class InvertedDoublePendulum(BraxEnv):
    """Balance two stacked poles on a cart; ends when the tip drops below 1 m."""

    brax_name = "inverted_double_pendulum"
    observation_size = 8
    masses = {
        "mass_cart": ("cart", 10.471975),
        "mass_pole": ("pole", 4.1987386),
        "mass_pole2": ("pole2", 4.1987386),
    }
    has_friction = False


@dataclasses.dataclass(frozen=True)
class Reacher(BraxEnv):
    """A two-link arm reaches a random target; reward −distance − control cost."""

    brax_name = "reacher"
    observation_size = 11
    masses = {"mass_body0": ("body0", 0.035604715), "mass_body1": ("body1", 0.039793506)}
    has_friction = False
    has_gravity = False  # the arm turns about vertical axes: gravity does no work on it

    @property
    def differentiable(self) -> bool:
        """On MJX, the checked pipeline: the arm touches nothing and its limit (±3 rad at the elbow)
        is not reached in ordinary motion, so brax's step is smooth in every feature; the masses act
        little (the joints' armature dominates the links' inertia)."""
        return self.backend == "mjx"


GOAL_BODY = "goal"
OBJECT_BODY = "object"
OBJECT_CLEARANCE = 0.17  # brax's Pusher starts the object at least this far (m) from the goal


@dataclasses.dataclass(frozen=True)
class Pusher(BraxEnv):
    """A seven-joint arm pushes a cylinder to a goal; reward −distances − control cost."""

    brax_name = "pusher"
    observation_size = 23
    masses = {
        "mass_shoulder_pan": ("r_shoulder_pan_link", 7.2935214),
        "mass_shoulder_lift": ("r_shoulder_lift_link", 3.1415927),
        "mass_upper_arm_roll": ("r_upper_arm_roll_link", 1.7140529),
        "mass_elbow_flex": ("r_elbow_flex_link", 0.40715042),
        "mass_forearm_roll": ("r_forearm_roll_link", 0.92818356),
        "mass_wrist_flex": ("r_wrist_flex_link", 0.005026548),
        "mass_wrist_roll": ("r_wrist_roll_link", 0.18346901),
    }
    stock_gravity = 0.0
    has_friction = False

    @classmethod
    def task_fields(cls):
        def goal(axis, default, lower, upper):
            return feature(
                default,
                lower,
                upper,
                unit="m",
                doc=f"{axis} of the goal the object is pushed to",
                affects=("start_state", "dynamics"),
            )

        return {
            "goal_position_x": goal("x", 0.45, -0.5, 1.0),
            "goal_position_y": goal("y", -0.05, -1.0, 1.0),
            "goal_position_z": goal("z", -0.323, -0.4, 0.5),
        }

    def task_system_changes(self, stock, values):
        goal = jnp.stack([values[f"goal_position_{axis}"] for axis in "xyz"])
        link = stock.link_names.index(GOAL_BODY)
        return {
            "body_pos": jnp.asarray(stock.body_pos).at[link + 1].set(goal),
            "link.transform.pos": jnp.asarray(stock.link.transform.pos).at[link].set(goal),
        }

    def init(self, key, context):
        """brax's reset, with the object kept ``OBJECT_CLEARANCE`` from the context's goal rather than
        the stock one: the object's slide joints (y, then x, measured from where the model places the
        object) are drawn as brax draws them, then pushed out radially from the goal to the clearance.
        At the default goal, which sits right below the object, this is brax's own reset."""
        from brax import math as brax_math  # brax loads with the environment (base.load_brax_env)

        env = self.brax_env(context)
        key_y, key_x, key_velocity = jax.random.split(key, 3)
        start = jnp.concatenate(
            [
                jax.random.uniform(key_y, (1,), minval=-0.3, maxval=-1e-6),
                jax.random.uniform(key_x, (1,), minval=-0.2, maxval=0.2),
            ]
        )
        stock = self.stock_system
        object_position = jnp.asarray(stock.body_pos)[stock.link_names.index(OBJECT_BODY) + 1]
        goal = jnp.stack(
            [
                context.goal_position_y - object_position[1],
                context.goal_position_x - object_position[0],
            ]
        )
        away = start - goal
        distance = brax_math.safe_norm(away)
        start = goal + away * jnp.where(
            distance < OBJECT_CLEARANCE, OBJECT_CLEARANCE / distance, 1.0
        )
        q = env.sys.init_q.at[-4:].set(jnp.concatenate([start, jnp.zeros(2)]))
        velocity = jax.random.uniform(
            key_velocity, (env.sys.qd_size(),), minval=-0.005, maxval=0.005
        )
        pipeline_state = env.pipeline_init(q, velocity.at[-4:].set(0.0))
        # brax's reset gives the rest of the state (rewards, metrics); its own physics is unused
        return env.reset(key).replace(
            pipeline_state=pipeline_state, obs=env._get_obs(pipeline_state)
        )

    def state_variables(self, state):
        """Joint positions and velocities, and where the goal is (a body the context places)."""
        link = self.stock_system.link_names.index(GOAL_BODY)
        return (*super().state_variables(state), state.pipeline_state.x.pos[link])

    @property
    def action_space(self):
        # brax's Pusher maps actions in [−1, 1] onto the actuators' control ranges itself.
        ones = np.ones(self._brax.sys.act_size(), np.float32)
        return type(super().action_space)(-ones, ones)
