"""gymnax 1.0's API: code written for gymnax 1.0 runs with ``import contextrl.gymnax.v1 as gymnax``.

    env, params = gymnax.make("CartPole-v1")               # params: the context and the time limit
    obs, state = env.reset(key, params)                    # state: CartPoleState(x, x_dot, ..., time)
    obs, state, reward, terminated, truncated, info = env.step(key, state, action, params)
    params = params.replace(length=0.8, max_steps_in_episode=100)

As in gymnax 1.0: ``params.max_steps_in_episode`` is the time limit, the state has gymnax's field names
(``state.replace(theta=...)``; gymnax's own state classes are accepted too), ``env.step_env`` is one
transition without the auto-reset, ``env.state_space(params)`` names the state's fields, transitions
stop gradients unless ``env.with_transition_gradients()`` (environments with a continuous action), and
``gymnax.register(id, factory)`` adds a user's own environment to ``make``. A bare context (a batch from
``crl.sample``) is accepted as params too, with ``make``'s time limit. The physics, start states and
keys are the core's: the same key and actions give the same transitions as ``contextrl.gymnax``.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

import contextrl.gymnax as face
from contextrl.context.features import ContextError
from contextrl.core.env import MAX_STEP_COUNT, Env, tree_where
from contextrl.core.env import EnvState as CoreState
from contextrl.core.spaces import Box, Discrete
from contextrl.envs.classic_control.cartpole import THETA_THRESHOLD, X_THRESHOLD, CartPoleContext
from contextrl.envs.classic_control.pendulum import NOMINAL_TORQUE
from contextrl.gymnax import GYMNAX_IDS, core_id, gymnax_space, make_core, registration

FLOAT32_MAX = float(np.finfo(np.float32).max)
# gymnax's params that contextrl computes from the context in every step rather than stores
DERIVED = {
    CartPoleContext: {
        "total_mass": lambda context: context.masscart + context.masspole,
        "polemass_length": lambda context: context.masspole * context.length,
        "theta_threshold_radians": lambda context: jnp.float32(THETA_THRESHOLD),
        "x_threshold": lambda context: jnp.float32(X_THRESHOLD),
    }
}


def time_limit(value: Any) -> jax.Array:
    """``max_steps_in_episode`` as the int32 the step counter is, checked where it is concrete."""
    if not isinstance(value, jax.core.Tracer):
        array = np.asarray(value)
        if array.dtype.kind not in "iu" or not np.all((array >= 1) & (array <= MAX_STEP_COUNT)):
            raise ValueError(
                f"max_steps_in_episode must be an integer in [1, {MAX_STEP_COUNT:,}], got {value!r}"
            )
    return jnp.asarray(value, jnp.int32)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class EnvParams:
    """gymnax's params: the environment's context (its features read by name, as gymnax's fields) and
    the time limit ``max_steps_in_episode``, which gymnax keeps in its params."""

    context: Any
    max_steps_in_episode: jax.Array

    def __getattr__(self, name: str) -> Any:
        context = self.__dict__.get("context")
        if context is None or name.startswith("__"):
            raise AttributeError(name)
        derived = DERIVED.get(type(context), {})
        if name in derived:
            return derived[name](context)
        try:
            return getattr(context, context.space.resolve(name))
        except ContextError as error:
            raise AttributeError(str(error)) from None

    def replace(self, **values: Any) -> EnvParams:
        """A copy with features (validated against their bounds) or the time limit changed."""
        limit = values.pop("max_steps_in_episode", self.max_steps_in_episode)
        derived = sorted(set(values) & set(DERIVED.get(type(self.context), {})))
        if derived:
            raise ContextError(
                f"{derived} follow from the context in every step; replace the features instead"
            )
        context = self.context.replace(**values) if values else self.context
        return EnvParams(context, time_limit(limit))


class State:
    """gymnax's state of one environment: the core's physics variables under gymnax's names, and
    ``time``; ``core`` is the core's state it views."""

    variables: ClassVar[tuple[str, ...]]

    @classmethod
    def of(cls, core: CoreState, action: Any = None) -> State:
        """The view of ``core`` (reached by ``action``, None after a reset)."""
        values = {name: core.physics[i] for i, name in enumerate(cls.variables)}
        return cls(**values, time=core.time)

    @property
    def core(self) -> CoreState:
        return CoreState(jnp.stack([getattr(self, name) for name in self.variables]), self.time)

    def replace(self, **values: Any) -> State:
        return dataclasses.replace(self, **values)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class CartPoleState(State):
    x: jax.Array
    x_dot: jax.Array
    theta: jax.Array
    theta_dot: jax.Array
    time: jax.Array

    variables = ("x", "x_dot", "theta", "theta_dot")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class PendulumState(State):
    theta: jax.Array
    theta_dot: jax.Array
    last_u: jax.Array  # the last action clipped to the action space (gymnax keeps it to render)
    time: jax.Array

    variables = ("theta", "theta_dot")

    @classmethod
    def of(cls, core: CoreState, action: Any = None) -> PendulumState:
        last_u = jnp.zeros((), jnp.float32) if action is None else jnp.reshape(action, ())
        theta, theta_dot = core.physics[0], core.physics[1]
        return cls(theta, theta_dot, jnp.clip(last_u, -NOMINAL_TORQUE, NOMINAL_TORQUE), core.time)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class MountainCarState(State):
    position: jax.Array
    velocity: jax.Array
    time: jax.Array

    variables = ("position", "velocity")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class AcrobotState(State):
    joint_angle1: jax.Array
    joint_angle2: jax.Array
    velocity_1: jax.Array
    velocity_2: jax.Array
    time: jax.Array

    variables = ("joint_angle1", "joint_angle2", "velocity_1", "velocity_2")


# gymnax's state class of each environment it shares with contextrl (the others step the core's state)
STATES = {
    "CartPole": CartPoleState,
    "Pendulum": PendulumState,
    "Acrobot": AcrobotState,
    "MountainCar": MountainCarState,
    "MountainCarContinuous": MountainCarState,
}


@dataclasses.dataclass(frozen=True)
class Dict:
    """A space per named field: gymnax's ``spaces.Dict`` where gymnax is not installed."""

    spaces: dict[str, Any]

    def contains(self, state: Any) -> bool:
        return all(space.contains(getattr(state, name)) for name, space in self.spaces.items())


class Environment(face.Environment):
    """A contextrl ``Env`` answering gymnax 1.0's calls (see the module's docstring)."""

    def __init__(self, env: Env, transition_gradients: bool = False):
        self._transition_gradients = transition_gradients
        self.state_class = STATES.get(env.name)
        super().__init__(env, "1.0")
        self.step_env = jax.jit(self._step_env)

    @property
    def name(self) -> str:
        """gymnax's id where gymnax has the environment, as gymnax's ``env.name`` is."""
        return GYMNAX_IDS.get(self.env.name, self.env.name)

    @property
    def default_params(self) -> EnvParams:
        return EnvParams(self.env.default_context(), time_limit(self.env.max_steps))

    @property
    def supports_transition_gradients(self) -> bool:
        """A continuous action has a derivative; a discrete one has none to offer."""
        return isinstance(self.env.action_space, Box)

    @property
    def transition_gradients_enabled(self) -> bool:
        return self._transition_gradients

    def with_transition_gradients(self) -> Environment:
        """A copy whose steps keep the gradients of the observation and state (gymnax stops them)."""
        if not self.supports_transition_gradients:
            raise ValueError(
                f"{self.name} does not support transition gradients: its action is discrete"
            )
        return Environment(self.env, transition_gradients=True)

    def state_space(self, params: Any = None) -> Any:
        """A space per state field: float32's range for each variable, the time below the limit."""
        if self.state_class is None:
            raise NotImplementedError(
                f"{self.name} steps contextrl's EnvState (physics, time), which has no gymnax space"
            )
        _, limit = self._split(params)
        names = [field.name for field in dataclasses.fields(self.state_class)]
        spaces = {name: Box(-FLOAT32_MAX, FLOAT32_MAX) for name in names if name != "time"}
        spaces["time"] = Discrete(int(limit))
        if importlib.util.find_spec("gymnax") is None:
            return Dict(spaces)
        from gymnax.environments import spaces as gymnax_spaces

        return gymnax_spaces.Dict({name: gymnax_space(space) for name, space in spaces.items()})

    def _split(self, params: Any) -> tuple[Any, jax.Array]:
        """(context, time limit) of gymnax-style params, or of a bare context with make's limit."""
        params = self.default_params if params is None else params
        if isinstance(params, EnvParams):
            return params.context, params.max_steps_in_episode
        return params, self.env.max_steps

    def _core_state(self, state: Any) -> CoreState:
        """The core's state of a gymnax-style state (this face's or gymnax's own class)."""
        if self.state_class is None:
            return state
        names = [field.name for field in dataclasses.fields(self.state_class)]
        if not all(hasattr(state, name) for name in names):
            raise TypeError(
                f"{self.name}: a state has the fields {names} (env.reset's), got "
                f"{type(state).__name__}"
            )
        physics = jnp.stack(
            [jnp.asarray(getattr(state, name)) for name in self.state_class.variables]
        )
        return CoreState(physics, jnp.asarray(state.time, jnp.int32))

    def _view(self, core: CoreState, action: Any = None) -> Any:
        return core if self.state_class is None else self.state_class.of(core, action)

    def _reset(self, key: jax.Array, params: Any = None) -> tuple[jax.Array, Any]:
        context, _ = self._split(params)
        state, timestep = self.env.reset(key, context)
        return timestep.obs, self._view(state)

    def _step_env(self, key: jax.Array, state: Any, action: Any, params: Any = None) -> tuple:
        """gymnax's ``step_env``: (obs, state, reward, terminated, info), no time limit, no reset."""
        context, _ = self._split(params)
        core, timestep = self.env.advance(key, self._core_state(state), action, context)
        obs, state = timestep.obs, self._view(core, action)
        if not self._transition_gradients:
            obs, state = jax.lax.stop_gradient((obs, state))
        discount = 1.0 - timestep.terminated.astype(jnp.float32)
        return obs, state, timestep.reward, timestep.terminated, {"discount": discount}

    def _step(self, key: jax.Array, state: Any, action: Any, params: Any = None) -> tuple:
        """gymnax 1.0's step: ``step_env``, the params' time limit, and the same-step auto-reset (keys
        split as the core's ``Env.step`` splits them)."""
        _, limit = self._split(params)
        step_key, reset_key = jax.random.split(key) if self.env.steps_need_key else (key, key)
        final_obs, advanced, reward, terminated, info = self._step_env(
            step_key, state, action, params
        )
        truncated = advanced.time >= limit
        done = terminated | truncated
        start_obs, restarted = self._reset(reset_key, params)
        info = {**info, "terminated": terminated, "truncated": truncated}
        return (
            tree_where(done, start_obs, final_obs),
            tree_where(done, restarted, advanced),
            reward,
            terminated,
            truncated,
            {**info, "final_observation": final_obs},
        )


def _builtin(env_id: str, **kwargs: Any) -> Environment:
    return Environment(make_core(env_id, **kwargs))


for _env_id in face.registered_envs:
    registration.register(_env_id, functools.partial(_builtin, _env_id))

register = registration.register
registered_envs = registration.registered_envs


def make(env_id: str, **kwargs: Any) -> tuple[Any, Any]:
    """``(env, default_params)`` for a registered id (gymnax's, contextrl's, or one a user
    ``register``ed) or a contextrl alias such as ``"CartPole"``; keyword arguments go to the factory
    (``crl.make``'s: ``max_steps`` gives the default ``max_steps_in_episode``)."""
    if env_id not in registration._registry:
        try:
            contextrl_id = core_id(env_id)
        except (KeyError, ValueError):
            contextrl_id = env_id  # registration.make names the registered ids
        env_id = GYMNAX_IDS.get(contextrl_id, contextrl_id)
    return registration.make(env_id, **kwargs)


__all__ = [
    "GYMNAX_IDS",
    "AcrobotState",
    "CartPoleState",
    "Dict",
    "EnvParams",
    "Environment",
    "MountainCarState",
    "PendulumState",
    "State",
    "make",
    "register",
    "registered_envs",
    "registration",
]
