"""The environment core: pure ``reset``/``step`` functions of an explicit context.

An environment writes four unbatched pieces (``init``, ``transition``, ``observe`` and its spaces); this
base class adds what every environment shares, once: the step counter and time limit (a truncation), the
same-step auto-reset that keeps the last observation in ``final_obs``, and the context observation. Nothing
here is jitted: callers compile once, at the edge (``jax.jit(jax.vmap(env.step))``).

Inputs are checked here, once for every environment, when ``reset`` and ``step`` are traced: the context's
type (a dict of feature values is converted), the action's dtype and shape, and, where they are
concrete (an eager call), the action's values. Values known only at run time inside a compiled program
(an out-of-range discrete action, a NaN) cannot raise there; :func:`checked` adds ``checkify`` checks
for them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import checkify

from contextrl.context.features import ContextError
from contextrl.context.observation import ContextObservation
from contextrl.core.spaces import Box, Discrete


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TimeStep:
    """What one reset or step returns. A dataclass, not a tuple, so fields can be added later.

    When an episode ends (``terminated`` or ``truncated``), ``obs`` is already the first observation of
    the next episode and ``final_obs`` the last one of the episode that ended; otherwise they are equal.
    ``reward``, ``terminated`` and ``truncated`` belong to the step just taken.
    """

    obs: jax.Array
    reward: jax.Array
    terminated: jax.Array
    truncated: jax.Array
    final_obs: jax.Array
    info: dict = dataclasses.field(default_factory=dict)

    @property
    def done(self) -> jax.Array:
        return self.terminated | self.truncated


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class EnvState:
    """The environment's own state (``physics``) and the number of steps taken in this episode."""

    physics: Any
    time: jax.Array


def tree_where(condition, on_true, on_false):
    """Pick whole pytrees by a scalar condition (under ``vmap``, per copy)."""
    return jax.tree_util.tree_map(lambda a, b: jnp.where(condition, a, b), on_true, on_false)


class ContextHelpers:
    """What JAX and host environments offer alike about their context (one copy, mixed into both)."""

    context_type: ClassVar[type]
    # Features the original environment had that cannot act here, each with why (``contextrl describe``,
    # and the error for a context that names one).
    left_out: ClassVar[dict[str, str]] = {}

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        declared = cls.__dict__.get("context_type")
        if isinstance(declared, type) and hasattr(declared, "space"):  # one class per environment
            declared.space.left_out.update(cls.left_out)

    @property
    def name(self) -> str:
        return type(self).__name__

    @property
    def context_space(self):
        return self.context_type.space

    def default_context(self):
        """The context that reproduces the original environment."""
        return self.context_space.default()

    def context(self, **values):
        """A validated context: the given features (names or paper aliases), defaults for the rest."""
        return self.context_space.make(**values)


# The largest count of steps an int32 counter holds: an episode's time limit, a training budget.
MAX_STEP_COUNT = 2**31 - 1


@dataclasses.dataclass(frozen=True)
class Env(ContextHelpers):
    """Base of every JAX environment: static configuration only, pure functions of (key, state, context).

    ``max_steps`` is the time limit (None: the original environment's); ``obs_context`` says which
    context features are appended to the observation (default: none, the original observation);
    ``run_time_checks`` adds the ``checkify`` checks of :func:`checked`.
    """

    max_steps: int | None = None
    obs_context: ContextObservation = ContextObservation()
    run_time_checks: bool = False

    default_max_steps: ClassVar[int]
    # True when ``transition`` draws random numbers; otherwise the step key goes to the reset unsplit.
    stochastic_transition: ClassVar[bool] = False
    # True when ``init``, ``transition`` and ``observe`` are differentiable functions of the float
    # context features and any termination is a threshold that ``termination_margin`` measures
    # (``contextrl.core.gradient`` differentiates the return through them).
    differentiable: ClassVar[bool] = False

    def __post_init__(self):
        if self.max_steps is None:
            object.__setattr__(self, "max_steps", self.default_max_steps)
        if isinstance(self.max_steps, bool) or not isinstance(self.max_steps, (int, np.integer)):
            raise ValueError(f"max_steps must be a positive integer, got {self.max_steps!r}")
        if not 1 <= self.max_steps <= MAX_STEP_COUNT:
            raise ValueError(
                f"max_steps must be a positive integer of at most {MAX_STEP_COUNT:,} (the step "
                f"counter is int32), got {self.max_steps!r}"
            )
        for name in self.obs_context.features:
            self.context_space.resolve(name)

    # ---- written by each environment -------------------------------------------------------------
    def init(self, key, context) -> Any:
        """A start state drawn for ``context``."""
        raise NotImplementedError

    def transition(self, key, state, action, context) -> tuple[Any, jax.Array, jax.Array]:
        """``(next_state, reward, terminated)`` for one action."""
        raise NotImplementedError

    def observe(self, state, context) -> jax.Array:
        """The original environment's observation of ``state``."""
        raise NotImplementedError

    def state_variables(self, state) -> Any:
        """The variables that make up ``state`` (positions, velocities…), without quantities a simulator
        caches from the model (a mass matrix depends on the masses). The checker compares these when it
        asks whether a feature changed the start state or the next state; by default the whole state."""
        return state

    def termination_margin(self, state, context) -> jax.Array | None:
        """How far ``state`` is from ending the episode, continuous in the state: negative once it has
        terminated, zero or positive while it goes on. None for an environment that never terminates."""
        return None

    def termination_bonus(self, context) -> jax.Array | float:
        """How much more the step that ends the episode earns than a step that goes on (a goal's
        reward). The return's gradient counts it in full and only the rest of that step's reward by
        the fraction of the step before ``termination_margin`` crosses zero; 0 by default."""
        return 0.0

    def step_info(self, state, context) -> dict:
        """Facts about ``state`` for ``TimeStep.info`` (after a step: the state before any reset)."""
        return {}

    @property
    def action_space(self) -> Discrete | Box:
        raise NotImplementedError

    @property
    def base_observation_space(self) -> Box:
        """The original observation's space, wide enough for every context inside the bounds."""
        raise NotImplementedError

    # ---- provided (the context helpers come from ContextHelpers) -------------------------------------
    @property
    def observation_space(self) -> Box:
        base = self.base_observation_space
        if self.obs_context.hidden:
            return base
        low, high = self.obs_context.bounds(self.context_space)
        return Box(np.concatenate([base.low, low]), np.concatenate([base.high, high]))

    def with_obs_context(self, features=None, *, contexts=None, normalize=False, noise=0.0) -> Env:
        """A copy that appends context features to the observation (None, "all", "varying", names)."""
        obs_context = ContextObservation.build(
            self.context_space, features, contexts=contexts, normalize=normalize, noise=noise
        )
        return dataclasses.replace(self, obs_context=obs_context)

    def _observation(self, state, context, key) -> jax.Array:
        obs = self.observe(state, context)
        if self.obs_context.hidden:
            return obs
        extra = self.obs_context.values(self.context_space, context, key)
        return jnp.concatenate([obs, extra])

    def _keys(self, key, count: int):
        return jax.random.split(key, count) if count > 1 else [key]

    def reset(self, key, context) -> tuple[EnvState, TimeStep]:
        """Start an episode under ``context``."""
        context = self.as_context(context)
        init_key, obs_key = self._keys(key, 2) if self.obs_context.noise > 0 else (key, None)
        physics = self.init(init_key, context)
        obs = self._observation(physics, context, obs_key)
        zero = jnp.zeros((), jnp.float32)
        false = jnp.zeros((), bool)
        return EnvState(physics, jnp.zeros((), jnp.int32)), TimeStep(
            obs, zero, false, false, obs, self.step_info(physics, context)
        )

    def step(self, key, state: EnvState, action, context) -> tuple[EnvState, TimeStep]:
        """One step; if the episode ends, the same call resets it under the same context."""
        return self.step_then_reset(key, state, action, context, context)

    @property
    def steps_need_key(self) -> bool:
        """Whether a step draws random numbers (a stochastic transition or a noisy context view)."""
        return self.stochastic_transition or self.obs_context.noise > 0

    def advance(self, key, state: EnvState, action, context) -> tuple[EnvState, TimeStep]:
        """One step under ``context`` and no restart: ``obs`` and ``final_obs`` are the same.

        ``key`` is used only when :attr:`steps_need_key`.
        """
        context = self.as_context(context)
        action = self.checked_action(action)
        transition_key, obs_key = key, None
        if self.stochastic_transition and self.obs_context.noise > 0:
            transition_key, obs_key = self._keys(key, 2)
        elif self.obs_context.noise > 0:
            obs_key = key
        physics, reward, terminated = self.transition(
            transition_key, state.physics, action, context
        )
        time = state.time + 1
        obs = self._observation(physics, context, obs_key)
        return EnvState(physics, time), TimeStep(
            obs,
            jnp.asarray(reward, jnp.float32),
            jnp.asarray(terminated, bool),
            time >= self.max_steps,
            obs,
            self.step_info(physics, context),
        )

    def step_then_reset(
        self, key, state: EnvState, action, context, reset_context
    ) -> tuple[EnvState, TimeStep]:
        """One step under ``context``; an episode that ends restarts under ``reset_context``."""
        step_key, reset_key = self._keys(key, 2) if self.steps_need_key else (key, key)
        advanced, timestep = self.advance(step_key, state, action, context)
        restarted, start = self.reset(reset_key, reset_context)
        done = timestep.done
        return tree_where(done, restarted, advanced), dataclasses.replace(
            timestep, obs=jnp.where(done, start.obs, timestep.obs)
        )

    def check_context(self, context) -> None:
        """Raise ContextError unless ``context`` is a valid context of this environment."""
        self.context_space.check(self.as_context(context))

    def as_context(self, context):
        """``context`` as this environment's context type; a dict of feature values is converted (and
        checked where its values are concrete), anything else refused, naming the type expected."""
        if isinstance(context, self.context_type):
            return context
        if isinstance(context, Mapping):
            return self.context_space.make(**context)
        raise ContextError(
            f"{self.name} expects a {self.context_type.__name__} (from env.context(...), "
            f"env.default_context() or crl.sample(env, ...)) or a dict of its feature values, "
            f"got {type(context).__name__}"
        )

    def checked_action(self, action) -> jax.Array:
        """``action`` as an array of the action space's dtype, refused (ValueError) when its kind or shape
        cannot be one; concrete values are checked too, traced ones under ``run_time_checks``."""
        space = self.action_space
        discrete = isinstance(space, Discrete)
        expected = (
            f"an integer in [0, {space.n})" if discrete else f"finite floats of shape {space.shape}"
        )
        kind = None if isinstance(action, (str, bytes)) else _dtype_kind(action)
        if kind is None or kind not in ("iu" if discrete else "iuf"):
            raise ValueError(
                f"{self.name}: an action is {expected}, got {_short(action)} "
                f"({type(action).__name__})"
            )
        if np.shape(action) != space.shape:
            raise ValueError(
                f"{self.name}: an action is {expected}, got shape {np.shape(action)} "
                f"({_short(action)})"
            )
        action = jnp.asarray(action, space.dtype)
        valid = (action >= 0) & (action < space.n) if discrete else jnp.all(jnp.isfinite(action))
        message = f"{self.name}: an action is {expected}, got {{}}"
        if not isinstance(action, jax.core.Tracer):
            if not bool(valid):
                raise ValueError(message.format(_short(action)))
        elif self.run_time_checks:
            checkify.check(valid, message, action)
        return action


def _dtype_kind(value) -> str | None:
    """NumPy's kind letter of ``value``'s dtype ("b", "i", "u", "f"…), None where it has none."""
    dtype = getattr(value, "dtype", None)
    if dtype is None:
        try:
            dtype = np.asarray(value).dtype
        except (TypeError, ValueError):
            return None
    return np.dtype(dtype).kind


def _short(value) -> str:
    """A short repr of a user's action for an error message."""
    if isinstance(value, (str, bytes, jax.core.Tracer)):
        text = repr(value)
    else:
        try:
            text = repr(np.asarray(value).tolist())
        except (TypeError, ValueError):
            text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def checked(env: Env) -> Env:
    """``env`` whose compiled steps also check what only run time knows: a discrete action outside
    [0, n) or a non-finite action is reported once the program is wrapped by ``checkify``::

        from jax.experimental import checkify
        step = checkify.checkify(jax.jit(crl.checked(env).step))
        error, (state, ts) = step(key, state, action, context)
        error.throw()  # checkify.JaxRuntimeError naming the environment and the action

    Unchecked, a compiled step does not look at those values (as in gymnax): the result of such an
    action is unspecified. Eager calls check concrete actions always.
    """
    return dataclasses.replace(env, run_time_checks=True)
