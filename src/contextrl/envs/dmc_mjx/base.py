"""The shared base of the dm_control family on MJX: the stock suite tasks as JAX environments.

The model is dm_control's own: the reference environment (:mod:`contextrl.envs.dmc`) loads the stock
task, and its compiled ``MjModel`` goes to MJX once per process. A context is a model per copy: the
fields each feature sets (``opt.gravity``, ``geom_friction``, ``dof_damping``, masses…) are replaced
inside the compiled step, from the stock values, exactly as the reference writes them into its
``MjModel`` (see :mod:`contextrl.envs.dmc.base`). Rewards and observations are dm_control's task
definitions, written here in JAX in each domain's module.

What is set at load, once, and why:

- Gravity: MJX reads the gravity flag statically, so a stock model that disables gravity (Finger,
  Fish) is loaded with the flag on and a zero gravity vector, which is the same physics; a positive
  ``gravity`` then acts per copy.
- The medium (``density``, ``viscosity``, ``wind``): MJX computes fluid forces only if the model had
  them at load, so a task with any of these features is loaded with the medium on; at the stock zero
  density and viscosity it adds exactly zero force.
- ``opt.tolerance`` is raised to :data:`SOLVER_TOLERANCE`: dm_control's 1e-8 is below float32's
  resolution, so MJX's solver would never meet it and always run all its iterations; the solution it
  stops at agrees with MuJoCo's to float32 precision (the parity tests).

A control step is ``n_sub_steps = max(1, round(control_timestep / timestep))`` physics steps, per copy,
in a loop that runs to the largest count in the batch, the others held. Afterwards the state's
positions and velocities are recomputed, as dm_control does after its sub-steps, so the observation
and reward read the state the step ended in; sensors of the acceleration stage (touch, force, IMU)
keep the values of the last sub-step, as in dm_control. A step whose state is no longer finite or
exceeds MuJoCo's 1e10 limit ends the episode as terminated with reward 0, where dm_control raises
its ``PhysicsError`` (MuJoCo resets the data, and the observation is read from that reset data).

Only PointMass declares its dynamics differentiable (``contextrl.core.gradient``). Walker, Quadruped
and Finger move through contacts: MJX's gradient through them is finite but not the return's (20
steps of Walker at its default context, the walker falling to the floor: up to 44 times the central
difference, with signs flipped, for ``geom_density``, ``density`` and ``viscosity``). Fish has no
contacts but was not checked, so it stays refused.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.core.env import Env
from contextrl.core.spaces import Box
from contextrl.envs.mujoco_mass import mass_constants, pose_tables
from contextrl.envs.quiet import quiet_mujoco

SOLVER_TOLERANCE = 1e-6
MAX_VALUE = 1e10  # MuJoCo's mjMAXVAL: a larger position, velocity or acceleration is a divergence
MEDIUM_FEATURES = ("density", "viscosity", "wind_x", "wind_y", "wind_z")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class DmcState:
    """MJX's data for one copy and the task's goal (Fish's target, Finger's turn target; else zeros)."""

    data: Any
    goal: jax.Array


@dataclasses.dataclass(frozen=True)
class Stock:
    """What a task's model is made of, loaded once per process: the reference's ``MjModel`` (names,
    ids, rendering), MJX's copy of it, the control step and the tables the mass constants need."""

    mj_model: Any
    model: Any
    blank: Any  # MJX data as MuJoCo's reset leaves it (what a diverged step is observed from)
    control_timestep: float
    tables: Any


@functools.cache
def reference(host_class: type, task: str):
    """The dm_control reference environment of a task (its stock values were read after one episode
    initialisation, as the stock task writes some there)."""
    return host_class(task)


@functools.cache
def load_stock(host_class: type, task: str, medium: bool, contacts: bool) -> Stock:
    """The task's stock model on MJX (see the module docstring for what is set at load)."""
    import mujoco

    with quiet_mujoco():  # the first import of MJX prints about optional packages
        from mujoco import mjx

    host = reference(host_class, task)
    mj_model = copy.deepcopy(host.physics.model.ptr)  # the reference's own model stays untouched
    if mj_model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_GRAVITY:
        mj_model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_GRAVITY)
        mj_model.opt.gravity[:] = 0.0
    if not contacts:
        mj_model.geom_contype[:] = 0
        mj_model.geom_conaffinity[:] = 0
    model = mjx.put_model(mj_model)
    opt = model.opt.replace(tolerance=SOLVER_TOLERANCE)
    if medium:
        opt = opt.replace(_impl=dataclasses.replace(opt._impl, has_fluid_params=True))
    model = model.replace(opt=opt)
    return Stock(
        mj_model=mj_model,
        model=model,
        blank=mjx.make_data(model),
        control_timestep=float(host.control_timestep),
        tables=pose_tables(mj_model),
    )


def refresh(model, data):
    """The position- and velocity-dependent quantities and sensors of ``data``'s state, as dm_control
    computes them after its sub-steps (``mj_step1``); acceleration-stage sensors keep their values."""
    from mujoco import mjx

    data = mjx.com_pos(model, mjx.kinematics(model, data))
    data = mjx.sensor_pos(model, data)
    return mjx.sensor_vel(model, mjx.com_vel(model, data))


# ---- dm_control's reward shaping, in JAX ----------------------------------------------------------
def tolerance(x, bounds=(0.0, 0.0), margin=0.0, sigmoid="gaussian", value_at_margin=0.1):
    """dm_control's ``rewards.tolerance``: 1 inside ``bounds``, falling with the distance outside them
    (in units of ``margin``) along ``sigmoid`` to ``value_at_margin`` at one margin."""
    lower, upper = bounds
    inside = (lower <= x) & (x <= upper)
    if margin == 0:
        return jnp.where(inside, 1.0, 0.0)
    distance = jnp.where(x < lower, lower - x, x - upper) / margin
    if sigmoid == "gaussian":
        scale = np.sqrt(-2 * np.log(value_at_margin))
        outside = jnp.exp(-0.5 * (distance * scale) ** 2)
    elif sigmoid == "linear":
        scaled = distance * (1 - value_at_margin)
        outside = jnp.where(jnp.abs(scaled) < 1, 1 - scaled, 0.0)
    elif sigmoid == "quadratic":
        scaled = distance * np.sqrt(1 - value_at_margin)
        outside = jnp.where(jnp.abs(scaled) < 1, 1 - scaled**2, 0.0)
    else:  # pragma: no cover - a programming error in a domain module
        raise ValueError(f"unknown sigmoid {sigmoid!r}")
    return jnp.where(inside, 1.0, outside)


def random_quaternion(key) -> jax.Array:
    """A unit quaternion uniform on the 3-sphere, drawn as dm_control draws it (a normalised normal)."""
    quaternion = jax.random.normal(key, (4,))
    return quaternion / jnp.linalg.norm(quaternion)


@dataclasses.dataclass(frozen=True)
class DmcMjxEnv(Env):
    """A dm_control suite task on MJX, its context applied to a model per copy.

    ``task`` picks one of the domain's :attr:`tasks`. Observations are the task's observation dict
    flattened in its key order (as the reference's); actions are the actuators' controls; an episode
    is 1,000 control steps and ends earlier only when the simulation diverges.
    """

    task: str | None = None

    host_class: ClassVar[type]  # the dm_control reference environment's class
    tasks: ClassVar[tuple[str, ...]]
    default_task: ClassVar[str]
    # False where a pair of the stock model's geoms has no MJX collision function; only for tasks that
    # disable contacts anyway (Fish).
    contacts: ClassVar[bool] = True
    default_max_steps = 1000

    def __post_init__(self):
        task = self.default_task if self.task is None else self.task
        if task not in self.tasks:
            raise ValueError(
                f"{self.name}: unknown task {task!r}; on MJX choose one of {self.tasks}"
            )
        object.__setattr__(self, "task", task)
        medium = bool(set(MEDIUM_FEATURES) & set(self.context_space.names))
        stock = load_stock(self.host_class, task, medium, self.contacts)
        object.__setattr__(self, "_stock", stock)
        super().__post_init__()

    # ---- the model per copy --------------------------------------------------------------------------
    @property
    def stock(self) -> Stock:
        """The task's stock model (MuJoCo's and MJX's copies) and what is derived from it once."""
        return self._stock

    @property
    def control_timestep(self) -> float:
        """Seconds of simulated time per action (the stock task's)."""
        return self._stock.control_timestep

    def model(self, context):
        """The stock MJX model with every field the context sets replaced (works on traced contexts)."""
        stock = self._stock.model
        values = context.as_dict()
        opt = {}
        if "gravity" in values:
            opt["gravity"] = jnp.asarray(stock.opt.gravity).at[2].set(-values["gravity"])
        if "timestep" in values:
            opt["timestep"] = values["timestep"]
        if "density" in values:
            opt["density"] = values["density"]
        if "viscosity" in values:
            opt["viscosity"] = values["viscosity"]
        wind = jnp.asarray(stock.opt.wind)
        for axis, name in enumerate(("wind_x", "wind_y", "wind_z")):
            if name in values:
                wind = wind.at[axis].set(values[name])
        opt["wind"] = wind
        changes: dict[str, Any] = {"opt": stock.opt.replace(**opt)}
        if "friction_tangential" in values:
            friction = jnp.asarray(stock.geom_friction)
            changes["geom_friction"] = friction.at[:, 0].multiply(values["friction_tangential"])
        if "joint_damping" in values:
            changes["dof_damping"] = jnp.asarray(stock.dof_damping) * values["joint_damping"]
        if "joint_stiffness" in values:
            changes["jnt_stiffness"] = jnp.asarray(stock.jnt_stiffness) * values["joint_stiffness"]
        if "actuator_strength" in values:
            strength = values["actuator_strength"]
            changes["actuator_gainprm"] = (
                jnp.asarray(stock.actuator_gainprm).at[:, :3].multiply(strength)
            )
            changes["actuator_biasprm"] = (
                jnp.asarray(stock.actuator_biasprm).at[:, :3].multiply(strength)
            )
            changes["actuator_forcerange"] = jnp.asarray(stock.actuator_forcerange) * strength
        ratio = self.mass_ratio(values)
        if ratio is not None:
            changes.update(self.mass_changes(ratio))
        changes.update(self.task_model_changes(values))
        return stock.replace(**changes)

    def mass_ratio(self, values) -> jax.Array | None:
        """Each body's mass relative to its stock mass under the context (None: the stock masses)."""
        if "geom_density" not in values:
            return None
        return jnp.full(self._stock.mj_model.nbody, values["geom_density"])

    def mass_changes(self, ratio) -> dict[str, jax.Array]:
        """Masses and inertias scaled per body, with the constants MuJoCo derives from them
        (:mod:`contextrl.envs.mujoco_mass`), the stock ones exactly where the masses are."""
        stock = self._stock.model
        stock_mass = jnp.asarray(stock.body_mass)
        mass = stock_mass * ratio
        inertia = jnp.asarray(stock.body_inertia) * ratio[:, None]
        derived = mass_constants(self._stock.tables, mass, inertia)
        unchanged = jnp.all(ratio == 1.0)
        derived = {
            name: jnp.where(unchanged, jnp.asarray(getattr(stock, name)), value)
            for name, value in derived.items()
        }
        return {"body_mass": mass, "body_inertia": inertia, **derived}

    def task_model_changes(self, values) -> dict[str, jax.Array]:
        """Model fields a domain's own features set (PointMass's arena); none by default."""
        return {}

    def sub_steps(self, context) -> jax.Array:
        """Physics steps per control step under ``context`` (the reference's rule)."""
        steps = jnp.round(self.control_timestep / context.timestep)
        return jnp.maximum(1, steps).astype(jnp.int32)

    # ---- the task, written by each domain -------------------------------------------------------------
    def start(self, key, model, data, context) -> tuple[Any, jax.Array]:
        """The episode's start: ``(data with qpos set, goal or None)`` before the forward pass."""
        raise NotImplementedError

    def task_observation(self, data, goal, context) -> list[jax.Array]:
        """The task's observation parts, in dm_control's order."""
        raise NotImplementedError

    def reward(self, data, goal, action, context) -> jax.Array:
        """The task's reward for the state a step ended in."""
        raise NotImplementedError

    # ---- the core Env pieces ---------------------------------------------------------------------------
    def init(self, key, context) -> DmcState:
        from mujoco import mjx

        model = self.model(context)
        data, goal = self.start(key, model, self._stock.blank, context)
        goal = jnp.zeros(3) if goal is None else goal
        return DmcState(mjx.forward(model, data), jnp.asarray(goal, jnp.float32))

    def transition(self, key, state: DmcState, action, context):
        from mujoco import mjx

        model = self.model(context)
        count = self.sub_steps(context)

        def physics_step(carry):
            step, data = carry
            return step + 1, mjx.step(model, data)

        data = state.data.replace(ctrl=action)
        _, data = jax.lax.while_loop(lambda c: c[0] < count, physics_step, (0, data))
        fresh = refresh(model, data)
        finite = [
            jnp.all(jnp.isfinite(x) & (jnp.abs(x) <= MAX_VALUE))
            for x in (fresh.qpos, fresh.qvel, data.qacc)
        ]
        diverged = ~(finite[0] & finite[1] & finite[2])
        blank = self._stock.blank.replace(ctrl=action)
        data = jax.tree_util.tree_map(lambda a, b: jnp.where(diverged, a, b), blank, fresh)
        reward = jnp.where(diverged, 0.0, self.reward(data, state.goal, action, context))
        return DmcState(data, state.goal), reward, diverged

    def observe(self, state: DmcState, context) -> jax.Array:
        parts = self.task_observation(state.data, state.goal, context)
        return jnp.concatenate([jnp.ravel(part) for part in parts]).astype(jnp.float32)

    def state_variables(self, state: DmcState):
        """Joint positions, velocities, actuator activations and the goal: MJX's other data fields are
        computed from them and the model."""
        return state.data.qpos, state.data.qvel, state.data.act, state.goal

    @property
    def action_space(self) -> Box:
        low, high = np.asarray(self._stock.mj_model.actuator_ctrlrange, np.float32).T
        return Box(low, high)

    @property
    def base_observation_space(self) -> Box:
        size = reference(self.host_class, self.task).base_observation_space.shape[0]
        return Box(np.full(size, -np.inf), np.full(size, np.inf))

    # ---- names to indices -------------------------------------------------------------------------------
    def index(self, kind: str, name: str) -> int:
        """The id of a named model element (``"body"``, ``"geom"``, ``"joint"``, ``"site"``…)."""
        import mujoco

        kinds = {
            "body": mujoco.mjtObj.mjOBJ_BODY,
            "geom": mujoco.mjtObj.mjOBJ_GEOM,
            "joint": mujoco.mjtObj.mjOBJ_JOINT,
            "site": mujoco.mjtObj.mjOBJ_SITE,
            "sensor": mujoco.mjtObj.mjOBJ_SENSOR,
        }
        index = mujoco.mj_name2id(self._stock.mj_model, kinds[kind], name)
        if index < 0:  # pragma: no cover - a programming error in a domain module
            raise KeyError(f"{self.name}: no {kind} named {name!r}")
        return index

    def sensor(self, data, name: str) -> jax.Array:
        """A named sensor's reading."""
        model = self._stock.mj_model
        index = self.index("sensor", name)
        start = int(model.sensor_adr[index])
        return data.sensordata[start : start + int(model.sensor_dim[index])]

    def qpos_address(self, joint: str) -> int:
        """Where a named hinge or slide joint's position lies in ``qpos``."""
        return int(self._stock.mj_model.jnt_qposadr[self.index("joint", joint)])

    def randomize_joints(self, key, data, joint_range) -> Any:
        """dm_control's ``randomize_limited_and_rotational_joints`` for hinge and slide joints: a
        limited one uniform in its range, an unlimited hinge uniform in [-π, π], others untouched.

        ``joint_range`` is the model's (it may be a context's). Ball and free joints are not in the
        tasks that call this."""
        import mujoco

        model = self._stock.mj_model
        qpos = data.qpos
        keys = jax.random.split(key, model.njnt)
        for joint in range(model.njnt):
            kind = int(model.jnt_type[joint])
            address = int(model.jnt_qposadr[joint])
            if kind not in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
                raise NotImplementedError(f"{self.name}: joint {joint} is neither hinge nor slide")
            if model.jnt_limited[joint]:
                low, high = joint_range[joint, 0], joint_range[joint, 1]
            elif kind == mujoco.mjtJoint.mjJNT_HINGE:
                low, high = -np.pi, np.pi
            else:
                continue
            qpos = qpos.at[address].set(
                jax.random.uniform(keys[joint], (), minval=low, maxval=high)
            )
        return data.replace(qpos=qpos)


def contacts_touching(data) -> jax.Array:
    """Whether any contact of MJX's candidate list is active (as ``ncon > 0`` in MuJoCo: a distance
    at or below its margin)."""
    contact = data._impl.contact
    if contact.dist.shape[0] == 0:
        return jnp.asarray(False)
    return jnp.any(contact.dist <= contact.includemargin)
