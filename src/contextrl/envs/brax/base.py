"""The shared machinery of the Brax family: one physical system per copy, built from its context.

In brax a ``System`` (an MJX model) is a pytree, so a context per copy is a system per copy: ``transition``
and ``init`` take the stock system loaded once at construction, replace the fields the context sets
(gravity, friction, masses…) with the context's values, and run brax's own reset and step on that
system. Under ``jax.vmap`` every copy carries its own system; changing a context value is an array
change, never a recompilation or a model reload.

Each environment (``environments.py``) declares its brax name, its observation size and the features its
model has (link masses, joint stiffness, contacts, a goal variant); the features themselves and how they
reach the physics are written once, here. Importing this module sets ``MUJOCO_GL=egl`` (headless
rendering; MuJoCo reads it when it is first imported, which brax does) unless it is already set.

Only Reacher on MJX declares its dynamics differentiable (``contextrl.core.gradient``): its arm
touches nothing. The tasks that move through contacts (the walkers, Pusher, the reaching tasks) give
finite gradients that are not the return's: 20 steps of Ant at its default context differ from central
differences by up to 134 times, with signs flipped (gravity, friction, actuator strength). The
inverted pendulums (no contacts, but terminations brax decides inside its step) and the other pipelines
were not checked. At exactly the stock masses the constants MuJoCo derives from them are the stock
ones (see ``_mass_changes``), so a mass's gradient there leaves out how they change: nothing in
Reacher, whose only constraint, the elbow's limit, is not reached in ordinary motion.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import os
import sys
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import ContextBase, context_type, feature
from contextrl.core.env import Env
from contextrl.core.spaces import Box
from contextrl.envs.mujoco_mass import mass_constants, pose_tables
from contextrl.envs.quiet import quiet_mujoco

os.environ.setdefault("MUJOCO_GL", "egl")

BACKENDS = ("mjx", "generalized", "spring", "positional")
# The maximal-coordinate pipelines model contact restitution and per-body angular velocity damping.
MAXIMAL_COORDINATE_BACKENDS = ("spring", "positional")
# Joint damping acts in the pipelines that integrate joint-space dynamics; joint springs in MJX only.
JOINT_DAMPING_BACKENDS = ("mjx", "generalized")
JOINT_STIFFNESS_BACKENDS = ("mjx",)
# The pipelines that read the mass-derived inverse weights (contact and joint-limit softness).
INVWEIGHT_BACKENDS = ("mjx", "generalized")
# MJX's pyramidal friction cones turn singular as friction goes to 0: Ant's stock model (friction 1)
# gave NaN at a scale of 0 and of 0.001, none at 0.005 (100 random steps, 4 runs each).
MIN_FRICTION_SCALE = 0.05

# CARL's 16 compass codes for the goal direction, clockwise from north (+y); east is +x, "forward".
COMPASS = (
    "N", "NNE", "NE", "ENE", "E", "ESE", "SE", "SSE",
    "S", "SSW", "SW", "WSW", "W", "WNW", "NW", "NNW",
)  # fmt: skip
PLANAR_COMPASS = ("E", "W")  # a planar walker moves along x only


def compass_angle(choices: tuple[str, ...], index) -> jax.Array:
    """The angle (radians, counter-clockwise from +x) of a compass code given by its index in ``choices``."""
    degrees = jnp.asarray([90.0 - 22.5 * COMPASS.index(c) for c in choices])
    return jnp.deg2rad(degrees[index])


@functools.cache
def load_brax_env(brax_name: str, backend: str, fluid: bool):
    """Brax's environment object with its stock system, loaded from its MJCF once per process.

    ``fluid`` switches on MJX's medium model (a static switch), so a viscosity from the context acts;
    at viscosity 0 the medium adds exactly zero force.
    """
    with quiet_mujoco():
        from brax import envs as brax_envs

        env = brax_envs.get_environment(brax_name, backend=backend)
    if fluid:
        impl = dataclasses.replace(env.sys.opt._impl, has_fluid_params=True)
        env.sys = env.sys.replace(opt=env.sys.opt.replace(_impl=impl))
    return env


def _scaled_mass_features(masses: dict[str, tuple[str, float]], backend: str) -> dict[str, Any]:
    """One absolute mass feature per named link, bounded to [0.1×, 10×] of the stock mass."""
    meaning = "its inertia scales with it"
    if backend in MAXIMAL_COORDINATE_BACKENDS:
        meaning = "value/default scales the effective mass and inertia brax's pipeline uses"
    return {
        name: feature(
            default,
            default / 10,
            default * 10,
            unit="kg",
            doc=f"mass of the {link} link; {meaning}",
        )
        for name, (link, default) in masses.items()
    }


@dataclasses.dataclass(frozen=True)
class BraxEnv(Env):
    """Base of the Brax environments: brax's task on a per-copy system built from the context.

    ``backend`` picks brax's physics pipeline (MJX, the maintained one, by default). ``goal=True`` (the
    walkers only) is CARL's goal variant: the reward is the progress toward a target ``target_distance``
    away in the compass direction ``target_direction``, and reaching it (within ``target_radius``) ends
    the episode. ``fluid=True`` (MJX only) adds MuJoCo's medium model and with it the ``viscosity``
    feature; it is off by default because MJX then evaluates the medium at every physics step, about
    4× the cost of a step on CPU (brax's own medium model, of the other pipelines, fails under jax 0.10).
    """

    backend: str = "mjx"
    goal: bool = False
    fluid: bool = False

    brax_name: ClassVar[str]
    observation_size: ClassVar[int]
    # feature name -> (brax link name, stock mass in kg)
    masses: ClassVar[dict[str, tuple[str, float]]] = {}
    stock_gravity: ClassVar[float] = 9.81
    # False where gravity cannot act (Reacher's arm moves in the horizontal plane).
    has_gravity: ClassVar[bool] = True
    stock_angular_damping: ClassVar[float] = 0.0
    # False where friction cannot act or could not be shown to (no contacts; Pusher's object is touched
    # only once the arm reaches it, and nothing presses it on the table without gravity).
    has_friction: ClassVar[bool] = True
    has_joint_damping: ClassVar[bool] = True
    # MJX integrates joint damping explicitly in brax's tasks: too much makes light links diverge.
    max_joint_damping: ClassVar[float] = 10.0
    has_joint_stiffness: ClassVar[bool] = False
    # The goal variant's compass codes; empty for tasks without one.
    goal_directions: ClassVar[tuple[str, ...]] = ()
    default_max_steps = 1000

    def __post_init__(self):
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {self.backend!r}")
        if self.goal and not self.goal_directions:
            raise ValueError(f"{self.name} has no goal variant; goal=True is for the walkers")
        if self.fluid and self.backend != "mjx":
            raise ValueError(f"fluid=True needs the mjx backend, got backend={self.backend!r}")
        features = context_class(type(self), self.backend, self.goal, self.fluid)
        object.__setattr__(self, "context_type", features)
        object.__setattr__(self, "_brax", type(self).load(self.backend, self.fluid))
        super().__post_init__()

    @classmethod
    def load(cls, backend: str, fluid: bool):
        """The task object holding the stock system (``sys``) and the control step (``dt``), loaded
        once per process: brax's own task, by default."""
        return load_brax_env(cls.brax_name, backend, fluid)

    # ---- the declared features ---------------------------------------------------------------------
    @classmethod
    def feature_fields(cls, backend: str, goal: bool, fluid: bool) -> dict[str, Any]:
        """The context features this task has under ``backend``: only those that act there."""
        gravity_doc = "gravitational acceleration, pointing down"
        if cls.stock_gravity == 0.0:
            gravity_doc += "; the stock model has none"
        fields = {}
        if cls.has_gravity:
            fields["gravity"] = feature(cls.stock_gravity, 0.0, 30.0, unit="m/s²", doc=gravity_doc)
        if cls.has_friction:
            fields["friction"] = feature(
                1.0, MIN_FRICTION_SCALE, 5.0, doc="scale of every geom's stock sliding friction"
            )
        if backend in MAXIMAL_COORDINATE_BACKENDS:
            fields["elasticity"] = feature(
                0.0,
                0.0,
                1.0,
                doc="restitution of every contact (the spring and positional pipelines)",
            )
            fields["ang_damping"] = feature(
                cls.stock_angular_damping,
                -10.0,
                0.0,
                unit="1/s",
                doc="rate of each body's angular velocity decay, ω ← exp(ang_damping·dt)·ω",
            )
        if fluid:
            fields["viscosity"] = feature(
                0.0, 0.0, 5.0, unit="Pa·s", doc="viscosity of the medium: drag on every body"
            )
        fields["actuator_strength"] = feature(
            1.0, 0.0, 5.0, doc="scale of every actuator's stock gear (torque per unit action)"
        )
        if cls.has_joint_damping and backend in JOINT_DAMPING_BACKENDS:
            fields["joint_damping"] = feature(
                1.0, 0.0, cls.max_joint_damping, doc="scale of every joint's stock damping"
            )
        if cls.has_joint_stiffness and backend in JOINT_STIFFNESS_BACKENDS:
            fields["joint_stiffness"] = feature(
                1.0, 0.0, 10.0, doc="scale of every joint's stock spring stiffness"
            )
        if _effective_mass_exponents(cls.brax_name, backend) != (0.0, 0.0):
            fields.update(_scaled_mass_features(cls.masses, backend))
        fields.update(cls.task_fields())
        if goal:
            fields.update(
                target_distance=feature(
                    100.0, 1.0, 1000.0, unit="m", doc="distance of the target from the origin",
                    affects=("goal",),
                ),
                target_direction=feature(
                    "E", 0, 0, kind="categorical", choices=cls.goal_directions,
                    doc="compass direction of the target (E is the stock forward, +x)",
                    affects=("goal",),
                ),
                target_radius=feature(
                    5.0, 0.1, 200.0, unit="m", doc="reaching within this distance ends the episode",
                    affects=("goal",),
                ),
            )  # fmt: skip
        return fields

    @classmethod
    def task_fields(cls) -> dict[str, Any]:
        """Features of this task only (Pusher's goal position); none by default."""
        return {}

    # ---- the per-copy system -----------------------------------------------------------------------
    def system(self, context):
        """The stock system with every field the context sets replaced (works on traced contexts)."""
        stock = self._brax.sys
        values = context.as_dict()
        changes = {}
        if "gravity" in values:
            gravity = jnp.asarray(stock.opt.gravity).at[2].set(-values["gravity"])
            changes.update({"opt.gravity": gravity, "gravity": gravity})
        if "friction" in values:
            friction = jnp.asarray(stock.geom_friction)
            changes["geom_friction"] = friction.at[:, 0].multiply(values["friction"])
        if "elasticity" in values:
            changes["elasticity"] = jnp.full_like(stock.elasticity, values["elasticity"])
            changes["ang_damping"] = values["ang_damping"]
        if "viscosity" in values:
            changes["opt.viscosity"] = values["viscosity"]
        strength = values["actuator_strength"]
        changes["actuator_gear"] = jnp.asarray(stock.actuator_gear).at[:, 0].multiply(strength)
        changes["actuator.gear"] = jnp.asarray(stock.actuator.gear) * strength
        if "joint_damping" in values:
            changes["dof_damping"] = jnp.asarray(stock.dof_damping) * values["joint_damping"]
            changes["dof.damping"] = jnp.asarray(stock.dof.damping) * values["joint_damping"]
        if "joint_stiffness" in values:
            changes["jnt_stiffness"] = jnp.asarray(stock.jnt_stiffness) * values["joint_stiffness"]
        if self.masses and set(self.masses) <= set(values):  # declared where they can act
            changes.update(self._mass_changes(stock, values))
        changes.update(self.task_system_changes(stock, values))
        return stock.tree_replace(changes)

    def _mass_changes(self, stock, values) -> dict[str, jax.Array]:
        """Masses set per link, each body's inertia scaled by the same ratio (density kept); on the
        pipelines that read them (MJX, generalized), the constants MuJoCo derives from the masses are
        recomputed (``contextrl.envs.mujoco_mass``), and are the stock ones where the masses are."""
        # MuJoCo's body 0 is the world; brax's links start at body 1.
        body_ids = np.array([stock.link_names.index(link) + 1 for link, _ in self.masses.values()])
        stock_mass = jnp.asarray(stock.body_mass)
        mass = stock_mass.at[body_ids].set(jnp.stack([values[n] for n in self.masses]))
        ratio = jnp.where(stock_mass > 0, mass / jnp.where(stock_mass > 0, stock_mass, 1.0), 1.0)
        inertia = jnp.asarray(stock.body_inertia) * ratio[:, None]
        changes = {
            "body_mass": mass,
            "body_inertia": inertia,
            "link.inertia.mass": mass[1:],
            "link.inertia.i": jnp.asarray(stock.link.inertia.i) * ratio[1:, None, None],
        }
        # The spring and positional pipelines use mass**e and inertia**e_i (e = 1 - brax's spring
        # scale): where 0 < e < 1 the ratio scales that effective value (so the link's is ratio**(1/e)).
        mass_exponent, inertia_exponent = _effective_mass_exponents(self.brax_name, self.backend)
        if 0 < mass_exponent < 1:
            link_mass = jnp.asarray(stock.link.inertia.mass)
            changes["link.inertia.mass"] = link_mass * ratio[1:] ** (1 / mass_exponent)
        if 0 < inertia_exponent < 1:
            scale = ratio[1:] ** (1 / inertia_exponent)
            changes["link.inertia.i"] = jnp.asarray(stock.link.inertia.i) * scale[:, None, None]
        if self.backend in INVWEIGHT_BACKENDS:
            stock_masses = jnp.all(mass == stock_mass)
            derived = mass_constants(_pose_tables(type(self), self.fluid), mass, inertia)
            derived = {
                name: jnp.where(stock_masses, jnp.asarray(getattr(stock, name)), value)
                for name, value in derived.items()
            }
            changes.update(derived)
            changes["link.invweight"] = derived["body_invweight0"][1:, 0]
            changes["dof.invweight"] = derived["dof_invweight0"]
        return changes

    def task_system_changes(self, stock, values) -> dict[str, jax.Array]:
        """Changes of this task only (Pusher's goal body); none by default."""
        return {}

    def brax_env(self, context):
        """Brax's environment object running on the system of ``context``."""
        env = copy.copy(self._brax)
        env.sys = self.system(context)
        return env

    @property
    def stock_system(self):
        """The system brax's task loads (with the medium model switched on when ``fluid``)."""
        return self._brax.sys

    @property
    def control_timestep(self) -> float:
        """Seconds of simulated time per action (brax's physics step × its frames per action)."""
        return float(self._brax.dt)

    def render_state(self, state, context, height: int = 240, width: int = 320) -> np.ndarray:
        """An RGB frame of ``state`` drawn by MuJoCo, headless, from the task's tracking camera when it
        has one; bodies the context moves (Pusher's goal) are drawn where the context puts them."""
        import mujoco

        model, data, renderer = _renderer(type(self), self.backend, self.fluid, height, width)
        stock = self._brax.sys  # only a task's own bodies (Pusher's goal) move with the context
        moved = self.task_system_changes(stock, context.as_dict()).get("body_pos", stock.body_pos)
        model.body_pos[:] = np.asarray(moved)
        self.paint(model, context)
        data.qpos[:], data.qvel[:] = (
            np.asarray(state.pipeline_state.q),
            np.asarray(state.pipeline_state.qd),
        )
        mujoco.mj_forward(model, data)
        camera = (
            "track" if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, "track") >= 0 else -1
        )
        renderer.update_scene(data, camera=camera)
        for position, radius, rgba in self.scene_markers(state, context):
            scene = renderer.scene
            if scene.ngeom < scene.maxgeom:
                scene.ngeom += 1
                mujoco.mjv_initGeom(
                    scene.geoms[scene.ngeom - 1],
                    mujoco.mjtGeom.mjGEOM_SPHERE,
                    np.full(3, radius),
                    np.asarray(position, np.float64),
                    np.eye(3).reshape(-1),
                    np.asarray(rgba, np.float32),
                )
        return renderer.render()

    def paint(self, model, context) -> None:
        """Colour the rendering model's geoms (``geom_rgba``) to show the context; nothing by default."""

    def scene_markers(self, state, context) -> list[tuple[np.ndarray, float, tuple]]:
        """Spheres (position, radius, RGBA) drawn over the scene that are not part of the model (a
        target held in the state); none by default."""
        return []

    # ---- the core Env pieces -----------------------------------------------------------------------
    @property
    def action_space(self) -> Box:
        ctrl_range = np.asarray(self._brax.sys.actuator_ctrlrange, np.float32)
        return Box(ctrl_range[:, 0], ctrl_range[:, 1])

    @property
    def base_observation_space(self) -> Box:
        return Box(np.full(self.observation_size, -np.inf), np.full(self.observation_size, np.inf))

    def init(self, key, context):
        return self.brax_env(context).reset(key)

    def transition(self, key, state, action, context):
        next_state = self.brax_env(context).step(state, action)
        reward, terminated = next_state.reward, next_state.done > 0.5
        if self.goal:
            target = self.target(context)
            before = jnp.linalg.norm(state.pipeline_state.x.pos[0, :2] - target)
            after = jnp.linalg.norm(next_state.pipeline_state.x.pos[0, :2] - target)
            # CARL's reward: progress toward the target only, no penalty for moving away
            reward = jnp.maximum(0.0, before - after)
            terminated = terminated | (after <= context.target_radius)
        return next_state, reward, terminated

    def observe(self, state, context) -> jax.Array:
        return state.obs

    def state_variables(self, state):
        """Joint positions and velocities: the rest of brax's state is derived from them and the model."""
        return state.pipeline_state.q, state.pipeline_state.qd

    def target(self, context) -> jax.Array:
        """The goal variant's target (x, y) in the world."""
        angle = compass_angle(self.goal_directions, context.target_direction)
        return context.target_distance * jnp.stack([jnp.cos(angle), jnp.sin(angle)])


@functools.cache
def _effective_mass_exponents(brax_name: str, backend: str) -> tuple[float, float]:
    """The exponents the pipeline raises link masses and inertias to: 1 - brax's spring scales on the
    spring and positional pipelines (0: that quantity is fixed at 1, so masses cannot act through it),
    1 elsewhere."""
    if backend not in MAXIMAL_COORDINATE_BACKENDS:
        return (1.0, 1.0)
    system = load_brax_env(brax_name, backend, False).sys
    return (1.0 - float(system.spring_mass_scale), 1.0 - float(system.spring_inertia_scale))


@functools.cache
def _pose_tables(env_class: type, fluid: bool):
    """The mass-independent tables of a task's model at its initial pose (``contextrl.envs.mujoco_mass``), made once."""
    return pose_tables(env_class.load("mjx", fluid).sys.mj_model)


@functools.cache
def _renderer(env_class: type, backend: str, fluid: bool, height: int, width: int):
    """A MuJoCo model copy, its data and a renderer for one task, made once per frame size."""
    import mujoco

    model = copy.deepcopy(env_class.load(backend, fluid).sys.mj_model)
    return model, mujoco.MjData(model), mujoco.Renderer(model, height=height, width=width)


@functools.cache
def context_class(env_class: type, backend: str, goal: bool, fluid: bool) -> type:
    """The context dataclass of one task under one backend, variant and medium (one class per set of
    features, made once, so every instance of the same configuration shares it)."""
    fields = env_class.feature_fields(backend, goal, fluid)
    name = env_class.__name__
    name += "Goal" if goal else ""
    name += "" if backend == "mjx" else backend.capitalize()
    name += "Fluid" if fluid else ""
    name += "Context"
    namespace = {
        "__annotations__": {n: float for n in fields},
        "__doc__": f"Context features of {env_class.__name__} ({backend} pipeline"
        + (", goal variant)." if goal else ")."),
        "__module__": __name__,
        "__qualname__": name,
        "left_out": env_class.left_out,
        **fields,
    }
    cls = context_type(type(name, (ContextBase,), namespace))
    setattr(sys.modules[__name__], name, cls)  # importable by name, so contexts pickle
    return cls
