"""How the single gymnasium environment steps: a compiled JAX environment or a host simulator.

Every backend starts episodes with the core's selection code (:class:`contextrl.core.ContextualEnv`
for JAX environments, :func:`contextrl.core.choose_context` for host simulators) and answers the same
calls (``begin`` a run, ``restart`` the next episode, ``advance`` one action), so the adapter above
owns seeding, options and gymnasium's API once. A JAX environment that also offers scalar physics
(``contextrl.core.scalar``) steps on the host between compiled starts.
"""

from __future__ import annotations

import dataclasses
import operator
import types
from collections.abc import Callable, Hashable
from typing import Any

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.sharding import SingleDeviceSharding

from contextrl.context.features import ContextSpace
from contextrl.context.observation import ContextObservation
from contextrl.context.schedule import ContextSchedule
from contextrl.core.contextual import ContextualEnv, choose_context
from contextrl.core.env import Env
from contextrl.core.host import HostEnv
from contextrl.core.spaces import Discrete
from contextrl.gymnasium.packing import Packer


def _float_bits(x: jax.Array) -> jax.Array:
    return lax.bitcast_convert_type(jnp.asarray(x, jnp.float32), jnp.uint32).ravel()


def _bits_float(bits: jax.Array) -> jax.Array:
    return lax.bitcast_convert_type(bits, jnp.float32)


def cpu_jit(function: Callable) -> Callable:
    """``jax.jit`` pinned to the CPU: one environment's step is far too small to gain from a GPU,
    where every call would add a kernel launch and two transfers. (The vector env stays on the
    default device, where many copies do gain.)"""
    cpu = SingleDeviceSharding(jax.devices("cpu")[0])
    return jax.jit(function, in_shardings=cpu, out_shardings=cpu)


def on_cpu(array: Any) -> jax.Array:
    return jax.device_put(array, jax.devices("cpu")[0])


def context_table(schedule: ContextSchedule) -> np.ndarray:
    """The context set as a float32 (contexts × features) array, (0, features) when resampling.

    Compiled programs take the set as this argument, so one program serves every set of a selector.
    """
    if schedule.resamples:
        return np.zeros((0, len(schedule.space)), np.float32)
    return np.asarray(schedule.space.to_array(schedule.contexts), np.float32)


@dataclasses.dataclass(frozen=True)
class FromTable:
    """A context set given as a (contexts × features) array: one gather per choice, not one per
    feature. The same choices as :class:`FromSet` over the same set (its selector, its indices)."""

    space: ContextSpace
    table: Any
    selector: Any

    @property
    def uses_key(self) -> bool:
        return self.selector.uses_key

    def __call__(self, key, episode):
        index = jnp.asarray(self.selector(key, episode, self.table.shape[0]), jnp.int32)
        return self.space.from_array(jnp.asarray(self.table)[index]), index


def schedule_provider(schedule: ContextSchedule, table) -> Any:
    """The provider of ``schedule`` with its set given as ``table`` (traced or not)."""
    if schedule.resamples:
        return schedule.provider
    return FromTable(schedule.space, table, schedule.provider.selector)


def contextual_env(env: Env, schedule: ContextSchedule, table) -> ContextualEnv:
    """The core contextual env of ``schedule`` with its set given as ``table``."""
    return ContextualEnv(env, schedule_provider(schedule, table))


# What the contextual env adds to ``TimeStep.info``; the rest is the environment's ``step_info``.
CONTEXT_INFO = ("context_id", "next_context_id")


def env_step_info(timestep) -> dict:
    """The environment's own facts of a step (``Env.step_info``: completed, died…), without the ids."""
    return {name: value for name, value in timestep.info.items() if name not in CONTEXT_INFO}


def info_to_host(values: dict) -> dict[str, Any]:
    """Step facts as Python scalars (bool, int, float) or NumPy arrays, for gymnasium's ``info``."""
    return {
        name: value.item() if np.ndim(value) == 0 else np.asarray(value)
        for name, value in values.items()
    }


_PROGRAM_CACHE: dict[Hashable, Any] = {}
PROGRAM_CACHE_SIZE = 64


def shared_program(key: Hashable | None, build: Callable[[], Any]) -> Any:
    """Compiled programs shared by every adapter with the same static configuration (``key``).

    Compiling costs far more than stepping; two adapters over the same env and selector reuse one
    program. A None key (something unhashable, e.g. a lambda's closure state) builds a private one.
    """
    if key is None:
        return build()
    if key not in _PROGRAM_CACHE:
        if len(_PROGRAM_CACHE) >= PROGRAM_CACHE_SIZE:
            _PROGRAM_CACHE.pop(next(iter(_PROGRAM_CACHE)))
        _PROGRAM_CACHE[key] = build()
    return _PROGRAM_CACHE[key]


class JaxPrograms:
    """One copy of the core contextual env, compiled: each call one uint32 vector in, one out.

    ``begin``/``restart`` (and ``*_with``, which take the episode's context) return the packed state,
    the first observation, the context vector, the environment's step facts (``Env.step_info``) and the
    context id; ``advance`` one step without a restart (a gymnasium single env restarts only when asked)
    returns the packed state, observation, reward, step facts and the two end flags.
    """

    def __init__(self, env: Env, schedule: ContextSchedule):
        self.env = env
        self.schedule = schedule
        self.space = env.context_space
        self.discrete = isinstance(env.action_space, Discrete)
        table = context_table(schedule)
        state = jax.eval_shape(
            lambda key: contextual_env(env, schedule, table).reset(key)[0], jax.random.key(0)
        )
        self.packer = Packer(state)
        started = jax.eval_shape(
            lambda key: contextual_env(env, schedule, table).reset(key)[1], jax.random.key(0)
        )
        self.info_packer = Packer(env_step_info(started))
        self.begin = cpu_jit(self._begin_fn)
        self.begin_with = cpu_jit(self._begin_with_fn)
        self.restart = cpu_jit(self._restart_fn)
        self.restart_with = cpu_jit(self._restart_with_fn)
        self.advance = cpu_jit(self._advance_fn)

    def _started(self, state, timestep):
        return jnp.concatenate(
            [
                self.packer.pack(state),
                _float_bits(timestep.obs),
                _float_bits(self.space.to_array(state.context)),
                self.info_packer.pack(env_step_info(timestep)),
                lax.bitcast_convert_type(state.context_id, jnp.uint32)[None],
            ]
        )

    def _override(self, words):
        """(context, context id) written after the key or carry: F context floats, then the id."""
        return self.space.from_array(_bits_float(words[:-1])), words[-1].astype(jnp.int32)

    def _begin_fn(self, head, table):
        cenv = contextual_env(self.env, self.schedule, table)
        return self._started(*cenv.reset(head[:2], head[2], head[3]))

    def _begin_with_fn(self, words, table):
        cenv = contextual_env(self.env, self.schedule, table)
        context, context_id = self._override(words[4:])
        return self._started(*cenv.reset(words[:2], words[2], words[3], context, context_id))

    def _restart_fn(self, carry, table):
        cenv = contextual_env(self.env, self.schedule, table)
        return self._started(*cenv.restart(self.packer.unpack(carry)))

    def _restart_with_fn(self, words, table):
        cenv = contextual_env(self.env, self.schedule, table)
        size = self.packer.size
        context, context_id = self._override(words[size:])
        state = self.packer.unpack(words[:size])
        return self._started(*cenv.restart(state, context, context_id))

    def _advance_fn(self, words):
        size = self.packer.size
        state = self.packer.unpack(words[:size])
        if self.discrete:
            action = lax.bitcast_convert_type(words[size], jnp.int32)
        else:
            action = _bits_float(words[size:]).reshape(self.env.action_space.shape)
        cenv = ContextualEnv(self.env, self.schedule.provider)  # advancing never selects
        state, timestep = cenv.advance(state, action)
        flags = jnp.stack([timestep.terminated, timestep.truncated]).astype(jnp.uint32)
        return jnp.concatenate(
            [
                self.packer.pack(state),
                _float_bits(timestep.obs),
                _float_bits(timestep.reward),
                self.info_packer.pack(env_step_info(timestep)),
                flags,
            ]
        )


class JaxBackend:
    """A JAX ``Env`` stepped through :class:`JaxPrograms`; the host keeps the packed state."""

    def __init__(self, env: Env, schedule: ContextSchedule):
        self.env = env
        self.schedule = schedule
        self.space = env.context_space
        key = schedule.selection_key
        self.programs = shared_program(
            None if key is None else ("single", env, key), lambda: JaxPrograms(env, schedule)
        )
        self.packer = self.programs.packer
        self.table = on_cpu(context_table(schedule))
        self.action_space = env.action_space.to_gymnasium()
        self.flat_space = env.observation_space.to_gymnasium()
        self.base_size = int(np.prod(env.base_observation_space.shape))
        self.obs_size = int(np.prod(env.observation_space.shape))
        self.carry: np.ndarray | None = None
        self.info_packer = self.programs.info_packer
        # The environment's facts of the last start or step (``Env.step_info``), for gymnasium's info.
        self.step_info: dict[str, Any] = {}
        self._discrete = self.programs.discrete
        action_words = 1 if self._discrete else int(np.prod(self.action_space.shape))
        self._buffer = np.zeros(self.packer.size + action_words, np.uint32)
        # Views and bound methods made once: per-step host work is a few NumPy calls.
        self._size = self.packer.size
        self._carry_slot = self._buffer[: self._size]
        self._action_slot = self._buffer[self._size :]
        self._advance = self.programs.advance

    # ---- host side ------------------------------------------------------------------------------------
    def _unpack_start(self, out: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        size, features = self.packer.size, len(self.space)
        self.carry = out[:size]
        obs = out[size : size + self.obs_size].view(np.float32).copy()
        context_start = size + self.obs_size
        context_vector = out[context_start : context_start + features].view(np.float32).copy()
        info_start = context_start + features
        self._read_step_info(out[info_start : info_start + self.info_packer.size])
        return obs, context_vector, int(out[-1].view(np.int32))

    def _read_step_info(self, words: np.ndarray) -> None:
        if self.info_packer.size:
            self.step_info = info_to_host(self.info_packer.unpack_host(words))

    @staticmethod
    def _override_words(override: tuple[np.ndarray, int]) -> np.ndarray:
        vector, context_id = override
        return np.concatenate(
            [
                np.asarray(vector, np.float32).view(np.uint32),
                np.array([context_id], np.int32).view(np.uint32),
            ]
        )

    def begin(
        self, key_bits: np.ndarray, copy: int, num_copies: int, override=None
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """A new run's first episode (global episode ``copy``): (observation, context vector, id).

        ``override``: (context vector, id) to run instead of the selector's choice.
        """
        head = np.concatenate([key_bits, np.array([copy, num_copies], np.uint32)])
        if override is None:
            return self._unpack_start(np.asarray(self.programs.begin(head, self.table)))
        words = np.concatenate([head, self._override_words(override)])
        return self._unpack_start(np.asarray(self.programs.begin_with(words, self.table)))

    def restart(self, override=None) -> tuple[np.ndarray, np.ndarray, int]:
        """The next episode of this copy (global episode + number of copies)."""
        if override is None:
            return self._unpack_start(np.asarray(self.programs.restart(self.carry, self.table)))
        words = np.concatenate([self.carry, self._override_words(override)])
        return self._unpack_start(np.asarray(self.programs.restart_with(words, self.table)))

    def _checked_action(self, action: Any) -> int | np.ndarray:
        """``action`` as an int (discrete) or a float32 array of the action's shape, else ValueError."""
        if self._discrete:
            try:
                index = operator.index(action)
            except TypeError:
                index = -1
            if not 0 <= index < self.action_space.n:
                raise ValueError(
                    f"action must be an integer in [0, {self.action_space.n}), got {action!r}"
                )
            return index
        values = np.asarray(action, np.float32)
        if values.shape != self.action_space.shape or not np.all(np.isfinite(values)):
            raise ValueError(
                f"action must be a finite float array of shape {self.action_space.shape}, "
                f"got {action!r}"
            )
        return values

    def advance(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        checked = self._checked_action(action)
        if self._discrete:
            self._action_slot[0] = checked
        else:
            self._action_slot[:] = checked.ravel().view(np.uint32)
        self._carry_slot[:] = self.carry
        out = np.asarray(self._advance(self._buffer))
        size = self._size
        self.carry = out[:size]
        values = out.view(np.float32)
        end = size + self.obs_size
        self._read_step_info(out[end + 1 : end + 1 + self.info_packer.size])
        return values[size:end].copy(), float(values[end]), bool(out[-2]), bool(out[-1])

    def physics_and_context(self) -> tuple[Any, Any]:
        """The current physics state and context as NumPy values (for rendering)."""
        state = self.packer.unpack_host(self.carry)
        return state.env_state.physics, state.context

    def close(self) -> None:
        """Nothing to release: the compiled functions are freed with the object."""


def steps_on_host(env: Env) -> bool:
    """Whether ``env`` offers the scalar host path (``host_transition`` and ``host_observe``) and its
    steps draw no random numbers (every draw comes from the JAX key, so those step in JAX) nor report
    facts (``step_info``, computed by the compiled step only)."""
    offers = callable(getattr(env, "host_transition", None)) and callable(
        getattr(env, "host_observe", None)
    )
    return offers and not env.steps_need_key and type(env).step_info is Env.step_info


class ScalarBackend(JaxBackend):
    """A JAX ``Env`` whose episodes start in the compiled program and then step on the host.

    A compiled call costs about 15 µs on a CPU whatever it computes; the same physics on Python floats
    (the env's ``host_transition``, written once against an array namespace together with its JAX
    ``transition``, see ``contextrl.core.scalar``) costs a few. Episodes start and restart through the
    compiled core (same contexts, same start states); each step then runs in Python and rounds the state
    and reward to float32, as the JAX path holds them. The host computes in double precision, so
    trajectories agree with the JAX backend's to float32 rounding, not bit for bit. Only deterministic
    steps run here: the episode ends where the core's would (``terminated`` or the time limit).
    """

    def __init__(self, env: Env, schedule: ContextSchedule):
        super().__init__(env, schedule)
        self._physics_words = self._physics_slice()
        self._host_transition = env.host_transition
        self._host_observe = env.host_observe
        self._max_steps = env.max_steps
        self._state: list[float] = []
        self._time = 0
        self._context: types.SimpleNamespace | None = None
        self._extra: list[float] = []  # the appended context values, constant through an episode

    def _physics_slice(self) -> slice:
        """Where the physics state (one float32 array) lies in the packed carry.

        Read straight from the carry: unpacking the whole pytree at every start would cost as much as
        several steps.
        """
        packer = self.packer
        leaf_ids = jax.tree_util.tree_unflatten(packer.treedef, range(len(packer.sizes)))
        leaf = leaf_ids.env_state.physics
        if not isinstance(leaf, int) or packer.dtypes[leaf] != np.float32:
            raise TypeError(
                f"{self.env.name}'s host path needs its physics state to be one float32 array"
            )
        start = sum(packer.sizes[:leaf])
        return slice(start, start + packer.sizes[leaf])

    def _host_start(self, started):
        obs, context_vector, index = started
        self._state = self.carry[self._physics_words].view(np.float32).tolist()
        self._time = 0
        self._context = types.SimpleNamespace(
            **dict(zip(self.space.names, context_vector.tolist(), strict=True))
        )
        self._extra = obs[self.base_size :].tolist()
        return obs, context_vector, index

    def begin(self, key_bits, copy, num_copies, override=None):
        return self._host_start(super().begin(key_bits, copy, num_copies, override))

    def restart(self, override=None):
        # The carry's physics is the episode's start (the host steps alone); a restart needs only the
        # carry's run key and episode index.
        return self._host_start(super().restart(override))

    def advance(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        checked = self._checked_action(action)
        action = checked if self._discrete else checked.ravel().tolist()
        state, reward, terminated = self._host_transition(self._state, action, self._context)
        rounded = np.array([*state, reward], np.float32).tolist()
        self._state = rounded[:-1]
        self._time += 1
        base = self._host_observe(self._state, self._context)
        obs = np.array([*base, *self._extra], np.float32)
        return obs, rounded[-1], bool(terminated), self._time >= self._max_steps

    def physics_and_context(self) -> tuple[Any, Any]:
        return np.asarray(self._state, np.float32), self.packer.unpack_host(self.carry).context


class HostBackend:
    """A ``HostEnv`` simulator; the adapter adds the time limit and the context observation.

    Each episode's context comes from :func:`contextrl.core.choose_context`, the JAX environments'
    selection code, with the same global episode index.
    """

    def __init__(
        self,
        env: HostEnv,
        schedule: ContextSchedule,
        obs_context: ContextObservation,
        max_steps: int,
    ):
        self.env = env
        self.schedule = schedule
        self.space = env.context_space
        self.obs_context = obs_context
        self.max_steps = max_steps
        self.action_space = env.action_space
        if isinstance(self.action_space, gymnasium.spaces.Box):
            bounds = (self.action_space.low, self.action_space.high)
            self._action_bounds = tuple(bound.ravel().tolist() for bound in bounds)
        base = env.base_observation_space
        self.base_space = base
        self.base_size = int(np.prod(base.shape))
        if obs_context.hidden:  # the original observation as it is (pixels keep shape and dtype)
            self.flat_space = base
        else:
            low, high = obs_context.bounds(self.space)
            self.flat_space = gymnasium.spaces.Box(
                np.concatenate([np.ravel(base.low), low]).astype(np.float32),
                np.concatenate([np.ravel(base.high), high]).astype(np.float32),
                dtype=np.float32,
            )
        self.obs_size = int(np.prod(self.flat_space.shape))
        self.table = on_cpu(context_table(schedule))
        self._choose = cpu_jit(self._choose_fn)
        self._values = cpu_jit(lambda context, key: obs_context.values(self.space, context, key))
        self.time = 0
        self.context = None
        self._run: tuple[np.ndarray, int, int] | None = None  # key bits, episode, number of copies
        self._episode_key = None
        self._fixed_extra: np.ndarray | None = None

    def _choose_fn(self, key_bits, episode, table):
        provider = schedule_provider(self.schedule, table)
        context, index, start_key = choose_context(provider, key_bits, episode)
        return self.space.to_array(context), index, jax.random.key_data(start_key)

    def _observation(self, base_obs) -> np.ndarray:
        if self.obs_context.hidden:
            return np.asarray(base_obs, self.flat_space.dtype)
        base_obs = np.asarray(base_obs, np.float32).ravel()
        if self._fixed_extra is not None:
            extra = self._fixed_extra
        else:
            key = jax.random.fold_in(self._episode_key, self.time)
            extra = np.asarray(self._values(self.context, key))
        return np.concatenate([base_obs, extra])

    def _start(self, rng, override) -> tuple[np.ndarray, np.ndarray, int]:
        key_bits, episode, _ = self._run
        chosen, index, start_key_bits = self._choose(key_bits, np.int32(episode), self.table)
        context_vector = np.asarray(chosen, np.float32)
        index = int(index)
        if override is not None:
            context_vector, index = np.asarray(override[0], np.float32), int(override[1])
        # Built with NumPy: ``from_array``'s JAX ops would cost milliseconds per reset on the host.
        self.context = self.space.context_class(
            **{
                name: np.asarray(value, feature.dtype)
                for (name, feature), value in zip(
                    self.space.features.items(), context_vector, strict=True
                )
            }
        )
        self._episode_key = jax.random.wrap_key_data(start_key_bits)
        self._fixed_extra = None
        if not self.obs_context.hidden and self.obs_context.noise == 0:
            self._fixed_extra = np.asarray(self._values(self.context, self._episode_key))
        self.time = 0
        base_obs = self.env.reset_physics(self.context, rng)
        return self._observation(base_obs), context_vector, index

    def begin(self, key_bits, copy, num_copies, override=None, *, rng=None):
        self._run = (key_bits, int(copy), int(num_copies))
        return self._start(rng, override)

    def restart(self, override=None, *, rng=None):
        key_bits, episode, num_copies = self._run
        self._run = (key_bits, episode + num_copies, num_copies)
        return self._start(rng, override)

    def advance(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        base_obs, reward, terminated = self.env.step_physics(self._checked_action(action))
        self.time += 1
        obs = self._observation(base_obs)
        return obs, float(reward), bool(terminated), self.time >= self.max_steps

    def _checked_action(self, action: Any) -> Any:
        """``action`` if it lies in the action space, else ValueError; ``Space.contains`` costs as
        much as a tenth of a Box2D step, so the common spaces are checked directly."""
        space = self.action_space
        if isinstance(space, gymnasium.spaces.Discrete):
            try:
                index = operator.index(action)
            except TypeError:
                index = None
            if index is not None and space.start <= index < space.start + space.n:
                return index
        elif isinstance(space, gymnasium.spaces.Box):
            values = np.asarray(action, space.dtype)
            low, high = self._action_bounds
            if values.shape == space.shape and all(
                lower <= value <= upper  # False for NaN
                for value, lower, upper in zip(values.ravel().tolist(), low, high, strict=True)
            ):
                return values
        elif space.contains(np.asarray(action, space.dtype)):
            return action
        raise ValueError(f"action {action!r} is outside the action space {space}")

    def close(self) -> None:
        self.env.close()
