"""The shared machinery of the paper's target-reaching tasks (Fetch, Grasp, UR5e), rebuilt on MJX.

brax dropped these tasks in 2023 (they were brax v0.0.x configurations of its first, maximal-coordinate
engine); here each is a MuJoCo model written from their published configuration and stepped by MJX
through brax's pipeline, with the same per-copy system as the rest of the family (``base.py``). What is
shared: the paper's features with their absolute defaults, how they reach the system, and the target —
drawn at ``target_radius + target_distance·U`` from the task's origin at a uniform random angle, counted
as reached within ``target_radius``, and moved to a fresh draw when reached, as in the original tasks.
The state keeps the target's random draws (U, the angle, Grasp's height fraction), not its position:
the position is computed from them and the context whenever it is needed, so the target features are
goal features that act at once, on every copy, without touching the physics.

Two features of the original engine have no counterpart in MJX and are not offered (``left_out``):
``angular_damping`` (a per-body decay of angular velocity) and the joints' anchoring springs. What
``joint_stiffness`` sets here is the other half of the original's joint springs: how hard a joint is
stopped at its angle limit (MuJoCo's limit constraint in its direct stiffness form).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import feature
from contextrl.core.spaces import Box
from contextrl.envs.brax.base import BraxEnv
from contextrl.envs.quiet import quiet_mujoco

# Toward 0 MJX's pyramidal friction cones turn singular: at its default context Fetch gave NaN at 0
# and 0.005 and flew off at 0.0001 (100 random steps, 4 runs each); with the checker's random contexts
# 0.02 gave NaN too. The paper's ice is 0.05.
MIN_FRICTION = 0.05
# The joint limits' damping (direct form, the constraint's velocity gain): held fixed, so that
# ``joint_stiffness`` changes only the stiffness of the limit.
LIMIT_DAMPING = 100.0


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TargetState:
    """brax's physics state, the current target's draws (U ∈ [0, 1), angle, height fraction), and how
    many targets this episode reached."""

    pipeline_state: Any
    target_draws: jax.Array
    hits: jax.Array


@dataclasses.dataclass(frozen=True)
class Physics:
    """A MuJoCo model loaded as a brax system, and how many physics steps make one control step."""

    sys: Any
    n_frames: int

    @property
    def dt(self) -> float:
        return float(self.sys.opt.timestep) * self.n_frames


@functools.cache
def load_physics(model_xml: str, n_frames: int) -> Physics:
    """The system of one task's MJCF, loaded once per process."""
    with quiet_mujoco():
        from brax.io import mjcf

        return Physics(mjcf.loads(model_xml), n_frames)


@dataclasses.dataclass(frozen=True)
class ReachingTask(BraxEnv):
    """Base of Fetch, Grasp and UR5e: a body (``effector``) is driven to targets the context places."""

    model_xml: ClassVar[str]
    n_frames: ClassVar[int]
    effector: ClassVar[str]  # the body whose distance to the target counts
    # the paper's defaults and the upper bounds of the features that scale a stock value
    actuator_strength: ClassVar[float]
    joint_angular_damping: ClassVar[float]
    joint_stiffness: ClassVar[float | None]  # None: the joints have no limits to stiffen
    target_distance: ClassVar[tuple[float, float, float]]  # default, lower, upper
    target_radius: ClassVar[tuple[float, float, float]]
    target_height: ClassVar[float]  # z of a target (Grasp: the feature's default)
    # the body ``torso_mass`` sets (stock 1 kg); None: the task has no torso_mass
    torso: ClassVar[str | None] = None
    stochastic_transition = True  # a reached target moves to a fresh random place

    brax_name = ""  # not one of brax's tasks
    left_out: ClassVar[dict[str, str]] = {
        "angular_damping": "MJX models no per-body decay of angular velocity (brax v1's angular_damping)",
    }

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls.torso:  # the one mass feature, through the family's mass machinery
            cls.masses = {"torso_mass": (cls.torso, 1.0)}

    def __post_init__(self):
        if self.backend != "mjx" or self.goal or self.fluid:
            raise ValueError(f"{self.name} runs on MJX only, with no goal or fluid variant")
        super().__post_init__()

    @classmethod
    def load(cls, backend: str, fluid: bool):
        return load_physics(cls.model_xml, cls.n_frames)

    # ---- the declared features ---------------------------------------------------------------------
    @classmethod
    def feature_fields(cls, backend: str, goal: bool, fluid: bool) -> dict[str, Any]:
        physics = load_physics(cls.model_xml, cls.n_frames)
        gravity = -float(physics.sys.opt.gravity[2])
        distance, radius = cls.target_distance, cls.target_radius
        return {
            "gravity": feature(
                gravity, 0.1, 30.0, unit="m/s²", doc="gravitational acceleration, pointing down"
            ),
            "friction": feature(0.6, MIN_FRICTION, 5.0, doc="sliding friction of every contact"),
            "actuator_strength": feature(
                cls.actuator_strength,
                1.0,
                10 * cls.actuator_strength,
                unit="N·m",
                doc="torque of every joint motor at full action",
            ),
            "joint_angular_damping": feature(
                cls.joint_angular_damping,
                0.0,
                360.0,
                unit="N·m·s/rad",
                doc="damping of every joint (torque per unit angular velocity)",
            ),
            **({} if cls.joint_stiffness is None else {"joint_stiffness": feature(
                cls.joint_stiffness, 1.0, 10 * cls.joint_stiffness, unit="1/s²",
                doc="stiffness of every joint's angle limit (acceleration per radian past it)",
            )}),
            **({} if cls.torso is None else {"torso_mass": feature(
                1.0, 0.1, 10.0, unit="kg", doc=f"mass of the {cls.torso} (its inertia scales with it)"
            )}),
            "target_distance": feature(
                distance[0], distance[1], distance[2], unit="m", affects=("goal", "observation"),
                doc="targets are drawn up to this far beyond target_radius from the origin",
            ),
            "target_radius": feature(
                radius[0], radius[1], radius[2], unit="m", affects=("goal", "observation"),
                doc="a target counts as reached within this distance; targets start beyond it",
            ),
        }  # fmt: skip

    def system(self, context):
        """The stock system with the context's gravity, friction, motors, joints and torso mass."""
        stock = self._brax.sys
        gravity = jnp.asarray(stock.opt.gravity).at[2].set(-context.gravity)
        changes = {
            "opt.gravity": gravity,
            "gravity": gravity,
            "geom_friction": jnp.asarray(stock.geom_friction).at[:, 0].set(context.friction),
            **self.actuator_changes(stock, context.actuator_strength),
            "dof_damping": self._joint_dofs(jnp.asarray(stock.dof_damping), context),
            "dof.damping": self._joint_dofs(jnp.asarray(stock.dof.damping), context),
        }
        if "joint_stiffness" in context.as_dict():  # offered where the joints have limits
            limited = np.asarray(stock.jnt_limited, bool)[:, None]
            solref = jnp.stack([-context.joint_stiffness, jnp.asarray(-LIMIT_DAMPING)])
            changes["jnt_solref"] = jnp.where(limited, solref, jnp.asarray(stock.jnt_solref))
        if self.masses:
            changes.update(self._mass_changes(stock, {"torso_mass": context.torso_mass}))
        return stock.tree_replace(changes)

    def actuator_changes(self, stock, strength) -> dict[str, jax.Array]:
        """Every motor's gear (torque at full action) set to ``strength``."""
        return {
            "actuator_gear": jnp.asarray(stock.actuator_gear).at[:, 0].set(strength),
            "actuator.gear": jnp.full_like(stock.actuator.gear, strength),
        }

    def _joint_dofs(self, damping, context):
        """``damping`` with every hinge's value set to the context's (a free joint's dofs keep theirs)."""
        hinges = np.asarray(self._brax.sys.dof_jntid)
        hinge = np.asarray(self._brax.sys.jnt_type)[hinges] == 3  # mjJNT_HINGE
        return jnp.where(hinge, context.joint_angular_damping, damping)

    # ---- targets -----------------------------------------------------------------------------------
    def target(self, state, context) -> jax.Array:
        """Where the current target is: ``target_radius + target_distance·U`` from the origin, at the
        drawn angle, at ``target_elevation``."""
        fraction, angle = state.target_draws[0], state.target_draws[1]
        distance = context.target_radius + context.target_distance * fraction
        elevation = self.target_elevation(state, context)
        return jnp.stack([distance * jnp.cos(angle), distance * jnp.sin(angle), elevation])

    def target_elevation(self, state, context) -> jax.Array:
        """The target's height above the floor: the task's fixed ``target_height``."""
        return jnp.asarray(self.target_height)

    def draw_target(self, key) -> jax.Array:
        """A fresh target's draws: U ∈ [0, 1), an angle uniform in [0, 2π), and a second U (Grasp's
        height fraction)."""
        return jax.random.uniform(key, (3,)) * jnp.array([1.0, 2 * jnp.pi, 1.0])

    def effector_position(self, pipeline_state) -> jax.Array:
        return pipeline_state.x.pos[self._link(self.effector)]

    def _link(self, name: str) -> int:
        return self._brax.sys.link_names.index(name)

    # ---- the core Env pieces -----------------------------------------------------------------------
    @property
    def action_space(self) -> Box:
        size = self._brax.sys.act_size()
        return Box(-np.ones(size, np.float32), np.ones(size, np.float32))

    def init(self, key, context):
        """The task's initial pose at rest (as the original tasks start) and a freshly drawn target."""
        from brax.mjx import pipeline

        sys = self.system(context)
        pipeline_state = pipeline.init(sys, self.initial_pose(), jnp.zeros(sys.qd_size()))
        return TargetState(pipeline_state, self.draw_target(key), jnp.asarray(0, jnp.int32))

    def transition(self, key, state, action, context):
        sys = self.system(context)
        after = self.physics_step(sys, state.pipeline_state, action)
        target = self.target(state, context)
        hit = jnp.linalg.norm(target - self.effector_position(after)) < context.target_radius
        reward = self.reward(state.pipeline_state, after, target, hit)
        draws = jnp.where(hit, self.draw_target(key), state.target_draws)
        next_state = TargetState(after, draws, state.hits + hit.astype(jnp.int32))
        return next_state, reward, jnp.asarray(False)

    def initial_pose(self) -> jax.Array:
        """The joint positions an episode starts from: the model's own (``qpos0``)."""
        return jnp.asarray(self._brax.sys.init_q)

    def physics_step(self, sys, pipeline_state, action):
        """``n_frames`` physics steps with the action as the motors' controls."""
        from brax.mjx import pipeline

        def frame(pipeline_state, _):
            return pipeline.step(sys, pipeline_state, action), None

        return jax.lax.scan(frame, pipeline_state, (), self.n_frames)[0]

    def reward(self, before, after, target, hit) -> jax.Array:
        """The task's reward for one control step that ends with ``hit`` (the target reached)."""
        raise NotImplementedError

    def progress(self, before, after, target) -> jax.Array:
        """The effector's displacement toward the target over one control step (the original tasks'
        progress terms weigh it: 0.1 in Fetch and UR5e, 1.5 in Grasp)."""
        position = self.effector_position(after)
        direction = (target - position) / (1e-6 + jnp.linalg.norm(target - position))
        return jnp.dot(position - self.effector_position(before), direction)

    def touching(self, physics, geoms: tuple[str, ...], other: str | None = None) -> jax.Array:
        """1 for each of the named geoms in contact with ``other`` (with anything: None), else 0."""
        contact = physics.contact
        model = self._brax.sys.mj_model
        touching = contact.dist < 0
        if other is not None:
            other_id = model.geom(other).id
            touching = touching & ((contact.geom1 == other_id) | (contact.geom2 == other_id))
        ids = [model.geom(name).id for name in geoms]
        return jnp.stack(
            [jnp.any(touching & ((contact.geom1 == g) | (contact.geom2 == g))) for g in ids]
        ).astype(jnp.float32)

    def step_info(self, state, context) -> dict:
        """``targets_reached``: how many targets this episode has reached so far."""
        return {"targets_reached": state.hits}

    def state_variables(self, state):
        """Joint positions and velocities (the target is the goal: where it is depends on the context)."""
        return state.pipeline_state.q, state.pipeline_state.qd

    def scene_markers(self, state, context) -> list[tuple[np.ndarray, float, tuple]]:
        """The target, drawn as a translucent sphere of radius ``target_radius``."""
        radius = float(context.target_radius)
        return [(np.asarray(self.target(state, context)), radius, (0.9, 0.2, 0.2, 0.35))]
