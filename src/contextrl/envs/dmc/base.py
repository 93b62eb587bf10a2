"""The shared base of the dm_control family: stock suite tasks with a context written into the model.

Each environment loads the stock task with ``dm_control.suite.load(domain, task)`` once and keeps the
compiled ``MjModel``. A context is applied at reset by writing model fields in place, always computed
from the stock values kept at construction, so switching back to the default context restores the
stock model exactly and a context switch costs microseconds instead of a recompile.

How each common feature reaches the model:

- ``gravity``: ``opt.gravity = (0, 0, -gravity)``. Where the stock model disables gravity (Finger,
  Fish) the default is 0 and a positive value turns the gravity flag on, so the feature really acts.
- ``friction_tangential``: scales column 0 of ``geom_friction`` (every geom; a contact uses the larger
  friction of its two geoms, so every contact's friction scales).
- ``timestep``: ``opt.timestep``. The control step (the time one action lasts) stays the stock one:
  ``n_sub_steps = max(1, round(control_timestep / timestep))`` physics steps per action, exact whenever
  ``timestep`` divides the stock control step; a timestep larger than the control step gives one
  physics step per action.
- ``joint_damping`` / ``joint_stiffness``: scale ``dof_damping`` / ``jnt_stiffness``.
- ``actuator_strength``: scales every actuator's force law (``actuator_gainprm[:, :3]``,
  ``actuator_biasprm[:, :3]`` and ``actuator_forcerange``), so the force for any control and state is
  ``actuator_strength`` times the stock force for motors and for the position servos of Quadruped and
  Fish alike. (Scaling ``actuator_gear`` instead would also move a servo's set-point.)
- ``geom_density``: scales every body's mass and rotational inertia (``body_mass``, ``body_inertia``),
  which is what scaling every geom's density does when masses come from geom volumes (true for every
  body of Walker, Quadruped, Fish and Finger); ``mj_setConst`` then recomputes the derived constants.
- ``density``, ``viscosity``, ``wind_x/y/z``: ``opt.density``, ``opt.viscosity``, ``opt.wind``. Wind
  acts through the medium, so it needs ``density`` or ``viscosity`` above 0 to move anything.

A feature is declared only where it changes the dynamics (the domain modules say which were left out
and why): a scale of a stock value that is zero everywhere, or friction in a model without contacts,
would be a feature that does nothing.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; must be set before MuJoCo loads

from typing import Any, ClassVar  # noqa: E402

import gymnasium  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from dm_control import suite  # noqa: E402
from dm_control.rl import control  # noqa: E402

from contextrl.context.features import feature  # noqa: E402
from contextrl.core.host import HostEnv  # noqa: E402

TIMESTEP_BOUNDS = (0.001, 0.1)
# Model constants mj_setConst derives from masses and the model state; kept as compiled so that the
# stock masses restore them exactly (recomputing would differ where a task moved a geom, e.g. Fish's
# target, whose bounding box the compiler computed at its XML position).
DERIVED_CONSTANTS = (
    "body_subtreemass",
    "body_invweight0",
    "dof_invweight0",
    "dof_M0",
    "tendon_invweight0",
    "tendon_length0",
    "actuator_acc0",
    "actuator_length0",
    "cam_pos0",
    "cam_mat0",
    "cam_poscom0",
    "light_pos0",
    "light_dir0",
    "light_poscom0",
    "bvh_aabb",
)
STATISTICS = ("meaninertia", "meanmass", "meansize", "extent", "center")


# ---- common feature declarations (each domain's context class lists the ones that act on it) --------
def gravity_feature(default: float = 9.81) -> Any:
    doc = "gravitational acceleration, pointing down"
    if default == 0.0:
        doc += "; the stock model disables gravity, a positive value enables it"
    return feature(default, 0.0, 100.0, unit="m/s²", doc=doc)


def friction_tangential_feature() -> Any:
    return feature(1.0, 0.0, 10.0, doc="scale of every geom's stock sliding friction")


def timestep_feature(default: float) -> Any:
    return feature(
        default,
        *TIMESTEP_BOUNDS,
        unit="s",
        doc="physics step; the control step stays the stock one (sub-steps adapt)",
    )


def joint_damping_feature() -> Any:
    return feature(1.0, 0.0, 10.0, doc="scale of every joint's stock damping")


def joint_stiffness_feature() -> Any:
    return feature(1.0, 0.0, 10.0, doc="scale of every joint's stock stiffness")


def actuator_strength_feature() -> Any:
    return feature(1.0, 0.0, 10.0, doc="scale of every actuator's force (gain, bias, force range)")


def geom_density_feature(lower: float = 0.1) -> Any:
    return feature(1.0, lower, 10.0, doc="scale of every body's mass and inertia")


def density_feature(default: float = 0.0) -> Any:
    return feature(default, 0.0, 20000.0, unit="kg/m³", doc="density of the surrounding medium")


def viscosity_feature(default: float = 0.0, upper: float = 10.0) -> Any:
    return feature(default, 0.0, upper, unit="Pa·s", doc="viscosity of the surrounding medium")


def wind_feature(axis: str, limit: float = 20.0) -> Any:
    return feature(
        0.0, -limit, limit, unit="m/s", doc=f"velocity of the medium along {axis} (needs a medium)"
    )


def task_seed(rng: np.random.Generator) -> int:
    """The seed given to the dm_control task's RandomState at a reset, drawn from the episode's rng.

    ``suite.load(domain, task, task_kwargs={"random": task_seed(rng)})`` reproduces the same episode.
    """
    return int(rng.integers(0, 2**32))


def stock_or_value(value: float, stock: float) -> float:
    """The stock float64 value when ``value`` is its float32 rounding, so defaults restore bit for bit."""
    return float(stock) if np.float32(stock) == np.float32(value) else float(value)


class DmcEnv(HostEnv):
    """A dm_control suite task on MuJoCo with a context applied to the compiled model in place.

    ``task`` picks any task of the domain (``dm_control.suite.TASKS_BY_DOMAIN``). Observations are
    the task's observation dict flattened in its (ordered) key order to float32; actions are the
    actuators' controls. The episode never terminates by itself (dm_control tasks end by time: the adapter's 1000-step limit is a
    truncation), except when the simulation diverges, which ends it as terminated with reward 0.
    """

    domain: ClassVar[str]
    default_task: ClassVar[str]
    default_max_steps = 1000
    render_camera: ClassVar[int] = 0

    def __init__(self, task: str | None = None, *, render_size: tuple[int, int] = (240, 320)):
        task = self.default_task if task is None else task
        tasks = suite.TASKS_BY_DOMAIN[self.domain]
        if task not in tasks:
            raise ValueError(f"{self.name}: unknown task {task!r}; choose one of {list(tasks)}")
        if len(render_size) != 2 or not all(
            isinstance(s, int) and 16 <= s <= 4096 for s in render_size
        ):
            raise ValueError(
                f"{self.name}: render_size must be (height, width) ints in [16, 4096], "
                f"got {render_size!r}"
            )
        self.task_name = task
        self.render_size = tuple(render_size)
        stock = suite.load(self.domain, task)
        self._physics = stock.physics
        self._task = stock.task
        self.control_timestep = float(stock.control_timestep())
        self._capture_stock()
        self._applied: dict[str, float] = {}
        self.n_sub_steps = int(round(self.control_timestep / self._physics.model.opt.timestep))
        parts = self._task.get_observation(self._physics)
        ends = np.cumsum([np.size(part) for part in parts.values()])
        self.observation_layout = {
            key: slice(int(end - np.size(part)), int(end))
            for (key, part), end in zip(parts.items(), ends, strict=True)
        }  # where each of the task's observations lies in the flat observation
        observation = self._observation()
        self.base_observation_space = gymnasium.spaces.Box(
            -np.inf, np.inf, shape=observation.shape, dtype=np.float32
        )
        low, high = self._physics.model.actuator_ctrlrange.T.astype(np.float32)
        self.action_space = gymnasium.spaces.Box(low, high, dtype=np.float32)
        self._action_shape = self.action_space.shape
        missing = set(self.context_space.names) - set(self._appliers())
        if missing:  # pragma: no cover - a programming error in a domain module
            raise TypeError(f"{self.name}: no way to apply features {sorted(missing)}")

    # ---- stock values ------------------------------------------------------------------------------
    def _capture_stock(self) -> None:
        """Keep the stock values every feature is computed from.

        Parameters are read after one episode initialisation, because some stock tasks write them
        there (Finger spin sets the spinner's damping); masses are read before, as compiled.
        """
        model = self._physics.model
        self._stock_mass = model.body_mass.copy()
        self._stock_inertia = model.body_inertia.copy()
        self._stock_constants = {
            name: getattr(model, name).copy() for name in DERIVED_CONSTANTS if hasattr(model, name)
        }
        self._stock_statistics = {name: np.copy(getattr(model.stat, name)) for name in STATISTICS}
        self._task.random.seed(0)
        with self._physics.reset_context():
            self._task.initialize_episode(self._physics)
        self._stock = {
            "timestep": float(model.opt.timestep),
            "gravity": model.opt.gravity.copy(),
            "disableflags": int(model.opt.disableflags),
            "density": float(model.opt.density),
            "viscosity": float(model.opt.viscosity),
            "wind": model.opt.wind.copy(),
            "friction": model.geom_friction.copy(),
            "damping": model.dof_damping.copy(),
            "stiffness": model.jnt_stiffness.copy(),
            "gainprm": model.actuator_gainprm.copy(),
            "biasprm": model.actuator_biasprm.copy(),
            "forcerange": model.actuator_forcerange.copy(),
        }

    # ---- HostEnv interface -------------------------------------------------------------------------

    @property
    def physics(self):
        """The dm_control Physics (model and data) this environment steps; read it, do not edit it."""
        return self._physics

    def reset_physics(self, context: Any, rng: np.random.Generator) -> np.ndarray:
        values = self.context_values(context)  # every check before anything changes
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"{self.name}: rng must be a numpy.random.Generator, got {rng!r}")
        self._apply_structure(values)
        self._task.random.seed(task_seed(rng))
        with self._physics.reset_context():
            self._task.initialize_episode(self._physics)
            self._apply_parameters(values)
            self._after_initialize(values)
        return self._observation()

    def step_physics(self, action) -> tuple[np.ndarray, float, bool]:
        action = self._check_action(action)
        self._task.before_step(action, self._physics)
        try:
            self._physics.step(self.n_sub_steps)
        except control.PhysicsError:
            return self._observation(), 0.0, True  # diverged (MuJoCo reset the state): episode over
        self._task.after_step(self._physics)
        reward = float(self._task.get_reward(self._physics))
        terminated = self._task.get_termination(self._physics) is not None
        return self._observation(), reward, terminated

    def render_frame(self) -> np.ndarray:
        height, width = self.render_size
        return self._physics.render(height, width, camera_id=self.render_camera)

    def close(self) -> None:
        self._physics.free()

    # ---- context ------------------------------------------------------------------------------------
    def context_values(self, context: Any) -> dict[str, float]:
        """The context as plain floats, checked (type, bounds, finite, unbatched, valid combination)."""
        values = super().context_values(context)
        self._check_combination(values)
        return values

    def _check_combination(self, values: dict[str, float]) -> None:
        """Raise ContextError for physically impossible combinations (domains override)."""

    def _appliers(self) -> set[str]:
        """Names of the features this class knows how to apply."""
        return {
            "gravity",
            "friction_tangential",
            "timestep",
            "joint_damping",
            "joint_stiffness",
            "actuator_strength",
            "geom_density",
            "density",
            "viscosity",
            "wind_x",
            "wind_y",
            "wind_z",
        }

    def _apply_structure(self, values: dict[str, float]) -> None:
        """Masses (and, in domains, geometry): applied before the episode starts, only when changed."""
        scale = values.get("geom_density", 1.0)
        if self._applied.get("geom_density", 1.0) != scale:
            model = self._physics.model
            model.body_mass[:] = self._stock_mass * scale
            model.body_inertia[:] = self._stock_inertia * scale
            self._set_const(stock=scale == 1.0)
            self._applied["geom_density"] = scale

    def _set_const(self, stock: bool) -> None:
        """Recompute the constants derived from masses (subtree masses, inverse weights, mean inertia
        …), or restore them as compiled when the masses are the stock ones."""
        model = self._physics.model
        if not stock:
            mujoco.mj_setConst(model.ptr, self._physics.data.ptr)
            return
        for name, value in self._stock_constants.items():
            getattr(model, name)[...] = value
        for name, value in self._stock_statistics.items():
            setattr(model.stat, name, value)

    def _apply_parameters(self, values: dict[str, float]) -> None:
        """Every feature that is a plain model parameter, from the stock values (cheap: no recompile)."""
        model, stock = self._physics.model, self._stock
        opt = model.opt
        if "timestep" in values:
            opt.timestep = stock_or_value(values["timestep"], stock["timestep"])
            self.n_sub_steps = max(1, int(round(self.control_timestep / opt.timestep)))
        if "gravity" in values:
            self._apply_gravity(values["gravity"])
        if "friction_tangential" in values:
            model.geom_friction[:, 0] = stock["friction"][:, 0] * values["friction_tangential"]
        if "joint_damping" in values:
            model.dof_damping[:] = stock["damping"] * values["joint_damping"]
        if "joint_stiffness" in values:
            model.jnt_stiffness[:] = stock["stiffness"] * values["joint_stiffness"]
        if "actuator_strength" in values:
            strength = values["actuator_strength"]
            model.actuator_gainprm[:, :3] = stock["gainprm"][:, :3] * strength
            model.actuator_biasprm[:, :3] = stock["biasprm"][:, :3] * strength
            model.actuator_forcerange[:] = stock["forcerange"] * strength
        if "density" in values:
            opt.density = stock_or_value(values["density"], stock["density"])
        if "viscosity" in values:
            opt.viscosity = stock_or_value(values["viscosity"], stock["viscosity"])
        for axis, name in enumerate(("wind_x", "wind_y", "wind_z")):
            if name in values:
                opt.wind[axis] = stock_or_value(values[name], stock["wind"][axis])

    def _apply_gravity(self, gravity: float) -> None:
        opt, stock = self._physics.model.opt, self._stock
        stock_magnitude = -float(stock["gravity"][2])
        disabled_in_stock = bool(stock["disableflags"] & mujoco.mjtDisableBit.mjDSBL_GRAVITY)
        if disabled_in_stock and gravity == 0.0:
            opt.disableflags = stock["disableflags"]
            opt.gravity[:] = stock["gravity"]
            return
        opt.disableflags = stock["disableflags"] & ~int(mujoco.mjtDisableBit.mjDSBL_GRAVITY)
        opt.gravity[:] = (0.0, 0.0, -stock_or_value(gravity, stock_magnitude))

    def _after_initialize(self, values: dict[str, float]) -> None:
        """Change the start state the stock task drew, inside the reset (domains override)."""

    # ---- observation and action --------------------------------------------------------------------
    def _observation(self) -> np.ndarray:
        parts = self._task.get_observation(self._physics).values()
        return np.concatenate([np.ravel(part) for part in parts], dtype=np.float32)

    def _check_action(self, action) -> np.ndarray:
        try:
            array = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise ValueError(f"{self.name}: action {action!r} is not a numeric array") from error
        if array.shape != self._action_shape:
            raise ValueError(
                f"{self.name}: action must have shape {self._action_shape}, got {array.shape}"
            )
        if not np.isfinite(array).all():
            raise ValueError(f"{self.name}: action {array} is not finite (NaN or inf)")
        return array
