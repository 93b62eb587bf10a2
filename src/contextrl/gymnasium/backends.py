"""How the single gymnasium environment steps: a compiled JAX environment or a host simulator.

A JAX environment that also offers scalar physics (``contextrl.core.scalar``) steps on the host between
compiled starts. Every backend answers the same three calls (``start`` an episode under a chosen context, ``advance`` one
action, draw a ``frame``), so the adapter above them owns everything else once: context sets and
selectors, observation modes, seeding and gymnasium's API.
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

from contextrl.context.observation import ContextObservation
from contextrl.core.env import Env
from contextrl.core.host import HostEnv
from contextrl.core.spaces import Discrete
from contextrl.gymnasium.packing import Packer
from contextrl.gymnasium.schedule import ContextSchedule

KEY_WORDS = 2  # uint32 words of a threefry key


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


def episode_keys(key_bits: jax.Array, episode: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(selection key, environment key) of one episode, from the seed's key and the episode index."""
    key = jax.random.fold_in(jax.random.wrap_key_data(key_bits), episode)
    select_key, env_key = jax.random.split(key)
    return select_key, env_key


def advance(env: Env, key, state, action, context):
    """One step without the automatic reset: a gymnasium single env resets only when asked.

    This is ``Env.step_then_reset`` minus the reset, which would cost as much again as the step itself
    and whose result the caller throws away. Keys are split only when something random needs them.
    """
    noisy = env.obs_context.noise > 0
    transition_key, obs_key = (
        jax.random.split(jax.random.fold_in(key, state.time))
        if env.stochastic_transition or noisy
        else (None, None)
    )
    physics, reward, terminated = env.transition(transition_key, state.physics, action, context)
    time = state.time + 1
    obs = env._observation(physics, context, obs_key)
    next_state = dataclasses.replace(state, physics=physics, time=time)
    return next_state, obs, reward, terminated, time >= env.max_steps


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
    """The compiled start and step of one env and one kind of schedule, each one vector in, one out.

    Only the schedule's selector or spec is baked in; the context set is the ``table`` argument.
    """

    def __init__(self, env: Env, schedule: ContextSchedule):
        self.env = env
        self.schedule = schedule
        self.space = env.context_space
        self.discrete = isinstance(env.action_space, Discrete)
        key = jax.random.key(0)
        state_shape = jax.eval_shape(lambda k, c: env.reset(k, c)[0], key, env.default_context())
        self.packer = Packer((state_shape, jax.random.key_data(key), env.default_context()))
        self.start = cpu_jit(self._start_fn)
        self.start_with = cpu_jit(self._start_with_fn)
        self.step = cpu_jit(self._step_fn)

    def _begin(self, env_key, context_vector, index):
        reset_key, step_key = jax.random.split(env_key)
        context = self.space.from_array(context_vector)
        state, timestep = self.env.reset(reset_key, context)
        carry = self.packer.pack((state, jax.random.key_data(step_key), context))
        return jnp.concatenate(
            [
                carry,
                _float_bits(timestep.obs),
                _float_bits(context_vector),
                lax.bitcast_convert_type(jnp.asarray(index, jnp.int32), jnp.uint32)[None],
            ]
        )

    def _start_fn(self, words, table):
        episode = words[KEY_WORDS].astype(jnp.int32)
        select_key, env_key = episode_keys(words[:KEY_WORDS], episode)
        context_vector, index = self.schedule.choose(select_key, episode, table)
        return self._begin(env_key, context_vector, index)

    def _start_with_fn(self, words):
        _, env_key = episode_keys(words[:KEY_WORDS], words[KEY_WORDS].astype(jnp.int32))
        context_vector = _bits_float(words[KEY_WORDS + 1 :])
        return self._begin(env_key, context_vector, jnp.int32(-1))

    def _step_fn(self, words):
        size = self.packer.size
        state, key_bits, context = self.packer.unpack(words[:size])
        if self.discrete:
            action = lax.bitcast_convert_type(words[size], jnp.int32)
        else:
            action = _bits_float(words[size:]).reshape(self.env.action_space.shape)
        key = jax.random.wrap_key_data(key_bits)
        state, obs, reward, terminated, truncated = advance(self.env, key, state, action, context)
        flags = jnp.stack([terminated, truncated]).astype(jnp.uint32)
        carry = self.packer.pack((state, key_bits, context))
        return jnp.concatenate([carry, _float_bits(obs), _float_bits(reward), flags])


class JaxBackend:
    """A JAX ``Env`` stepped through :class:`JaxPrograms`; the host keeps the packed state."""

    def __init__(self, env: Env, schedule: ContextSchedule):
        self.env = env
        self.schedule = schedule
        self.space = env.context_space
        key = schedule.program_key
        self.programs = shared_program(
            None if key is None else ("single", env, key), lambda: JaxPrograms(env, schedule)
        )
        self.packer = self.programs.packer
        self.table = on_cpu(schedule.table)
        self.action_space = env.action_space.to_gymnasium()
        self.flat_space = env.observation_space.to_gymnasium()
        self.base_size = int(np.prod(env.base_observation_space.shape))
        self.obs_size = int(np.prod(env.observation_space.shape))
        self.carry: np.ndarray | None = None
        self._discrete = self.programs.discrete
        action_words = 1 if self._discrete else int(np.prod(self.action_space.shape))
        self._buffer = np.zeros(self.packer.size + action_words, np.uint32)
        # Views and bound methods made once: per-step host work is a few NumPy calls.
        self._size = self.packer.size
        self._carry_slot = self._buffer[: self._size]
        self._action_slot = self._buffer[self._size :]
        self._step = self.programs.step

    # ---- host side ------------------------------------------------------------------------------------
    def _unpack_start(self, out: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        size, features = self.packer.size, len(self.space)
        self.carry = out[:size]
        obs = out[size : size + self.obs_size].view(np.float32).copy()
        context_start = size + self.obs_size
        context_vector = out[context_start : context_start + features].view(np.float32).copy()
        return obs, context_vector, int(out[-1].view(np.int32))

    def start(
        self, key_bits: np.ndarray, episode: int, rng: np.random.Generator, context=None
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """Begin an episode: (observation, context vector, set index or -1)."""
        head = np.concatenate([key_bits, np.array([episode], np.uint32)])
        if context is None:
            return self._unpack_start(np.asarray(self.programs.start(head, self.table)))
        words = np.concatenate([head, np.asarray(context, np.float32).view(np.uint32)])
        return self._unpack_start(np.asarray(self.programs.start_with(words)))

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

    def _write_action(self, action: Any) -> None:
        """Validate ``action`` and write its bits into the input vector's action slot."""
        checked = self._checked_action(action)
        if self._discrete:
            self._action_slot[0] = checked
        else:
            self._action_slot[:] = checked.ravel().view(np.uint32)

    def advance(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        self._write_action(action)
        self._carry_slot[:] = self.carry
        out = np.asarray(self._step(self._buffer))
        size = self._size
        self.carry = out[:size]
        values = out.view(np.float32)
        end = size + self.obs_size
        return values[size:end].copy(), float(values[end]), bool(out[-2]), bool(out[-1])

    def physics_and_context(self) -> tuple[Any, Any]:
        """The current physics state and context as NumPy values (for rendering)."""
        state, _, context = self.packer.unpack_host(self.carry)
        return state.physics, context

    def close(self) -> None:
        """Nothing to release: the compiled functions are freed with the object."""


def steps_on_host(env: Env) -> bool:
    """Whether ``env`` offers the scalar host path (``host_transition`` and ``host_observe``) and its
    appended context values stay constant through an episode (no observation noise)."""
    offers = callable(getattr(env, "host_transition", None)) and callable(
        getattr(env, "host_observe", None)
    )
    return offers and env.obs_context.noise == 0


class ScalarBackend(JaxBackend):
    """A JAX ``Env`` whose episodes start in the compiled program and then step on the host.

    A compiled call costs about 15 µs on a CPU whatever it computes; the same physics on Python floats
    (the env's ``host_transition``, written once against an array namespace together with its JAX
    ``transition``, see ``contextrl.core.scalar``) costs a few. Episodes start through the compiled start
    program, so contexts and start states are exactly the JAX backend's; each step then runs in Python and
    rounds the state and reward to float32, as the JAX path holds them. The host computes in double
    precision, so trajectories agree with the JAX backend's to float32 rounding, not bit for bit. A
    transition's own randomness (Acrobot's torque noise) comes from the NumPy Generator ``start`` is
    given (the gymnasium env's ``np_random``, seeded by ``reset(seed=...)``), not from JAX keys.
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
        self._rng: np.random.Generator | None = None

    def _physics_slice(self) -> slice:
        """Where the physics state (one float32 array) lies in the packed start carry.

        Read straight from the carry: unpacking the whole pytree at every start would cost as much as
        several steps.
        """
        packer = self.packer
        leaf_ids = jax.tree_util.tree_unflatten(packer.treedef, range(len(packer.sizes)))
        leaf = leaf_ids[0].physics
        if not isinstance(leaf, int) or packer.dtypes[leaf] != np.float32:
            raise TypeError(
                f"{self.env.name}'s host path needs its physics state to be one float32 array"
            )
        start = sum(packer.sizes[:leaf])
        return slice(start, start + packer.sizes[leaf])

    def start(
        self, key_bits: np.ndarray, episode: int, rng: np.random.Generator, context=None
    ) -> tuple[np.ndarray, np.ndarray, int]:
        obs, context_vector, index = super().start(key_bits, episode, rng, context)
        self._state = self.carry[self._physics_words].view(np.float32).tolist()
        self._time = 0
        self._context = types.SimpleNamespace(
            **dict(zip(self.space.names, context_vector.tolist(), strict=True))
        )
        self._extra = obs[self.base_size :].tolist()
        self._rng = rng
        return obs, context_vector, index

    def advance(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        checked = self._checked_action(action)
        action = checked if self._discrete else checked.ravel().tolist()
        state, reward, terminated = self._host_transition(
            self._state, action, self._context, self._rng
        )
        rounded = np.array([*state, reward], np.float32).tolist()
        self._state = rounded[:-1]
        self._time += 1
        base = self._host_observe(self._state, self._context)
        obs = np.array([*base, *self._extra], np.float32)
        return obs, rounded[-1], bool(terminated), self._time >= self._max_steps

    def physics_and_context(self) -> tuple[Any, Any]:
        _, _, context = self.packer.unpack_host(self.carry)
        return np.asarray(self._state, np.float32), context


class HostBackend:
    """A ``HostEnv`` simulator; the adapter adds the time limit and the context observation."""

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
        if (
            obs_context.hidden
        ):  # the original observation as it is (pixels keep their shape and dtype)
            self.flat_space = base
        else:
            low, high = obs_context.bounds(self.space)
            self.flat_space = gymnasium.spaces.Box(
                np.concatenate([np.ravel(base.low), low]).astype(np.float32),
                np.concatenate([np.ravel(base.high), high]).astype(np.float32),
                dtype=np.float32,
            )
        self.obs_size = int(np.prod(self.flat_space.shape))
        self.table = on_cpu(schedule.table)
        self._choose = cpu_jit(self._choose_fn)
        self._values = cpu_jit(lambda context, key: obs_context.values(self.space, context, key))
        self.time = 0
        self.context = None
        self._episode_key = None
        self._fixed_extra: np.ndarray | None = None

    def _choose_fn(self, key_bits, episode):
        select_key, env_key = episode_keys(key_bits, episode)
        context_vector, index = self.schedule.choose(select_key, episode, self.table)
        return context_vector, index, jax.random.key_data(env_key)

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

    def start(
        self, key_bits: np.ndarray, episode: int, rng: np.random.Generator, context=None
    ) -> tuple[np.ndarray, np.ndarray, int]:
        chosen, index, env_key_bits = self._choose(key_bits, np.int32(episode))
        context_vector = np.asarray(chosen if context is None else context, np.float32)
        index = -1 if context is not None else int(index)
        # Built with NumPy: ``from_array``'s JAX ops would cost milliseconds per reset on the host.
        self.context = self.space.context_class(
            **{
                name: np.asarray(value, feature.dtype)
                for (name, feature), value in zip(
                    self.space.features.items(), context_vector, strict=True
                )
            }
        )
        self._episode_key = jax.random.wrap_key_data(env_key_bits)
        self._fixed_extra = None
        if not self.obs_context.hidden and self.obs_context.noise == 0:
            self._fixed_extra = np.asarray(self._values(self.context, self._episode_key))
        self.time = 0
        base_obs = self.env.reset_physics(self.context, rng)
        return self._observation(base_obs), context_vector, index

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
