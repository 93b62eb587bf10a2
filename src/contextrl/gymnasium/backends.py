"""How the single gymnasium environment steps: two backends, compiled JAX programs or a host simulator.

Both start episodes with the core's selection code (:class:`contextrl.core.ContextualEnv` in compiled
programs, :func:`contextrl.core.choose_context` for host simulators) and answer the same calls (``begin``
a run, ``restart`` the next episode, ``advance`` one action), so the adapter above owns seeding, options
and gymnasium's API once. A JAX environment that offers scalar physics (``contextrl.core.scalar``) is one
more host simulator (:class:`ScalarPhysics`), not a third backend. Every face, single or vector, checks
actions with :func:`action_check`.
"""

from __future__ import annotations

import operator
import types
from collections.abc import Callable, Hashable
from typing import Any

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import SingleDeviceSharding

from contextrl.context.changes import Change
from contextrl.context.observation import ContextObservation
from contextrl.context.schedule import ContextSchedule
from contextrl.context.selectors import FromSet
from contextrl.core.contextual import ContextualEnv, choose_context
from contextrl.core.env import Env
from contextrl.core.spaces import Discrete
from contextrl.gymnasium.frames import (
    Given,
    HostStart,
    Run,
    Started,
    StartRequest,
    Stepped,
    key_data,
)
from contextrl.gymnasium.packing import PackedProgram, Packer


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


def schedule_provider(schedule: ContextSchedule, table) -> Any:
    """The provider of ``schedule`` with its set given as ``table`` (traced or not): the same
    :class:`FromSet`, over the contexts the table holds."""
    if schedule.resamples:
        return schedule.provider
    return FromSet(schedule.space.from_array(table), schedule.provider.selector)


def contextual_env(
    env: Env, schedule: ContextSchedule, table, changes: Change | None = None
) -> ContextualEnv:
    """The core contextual env of ``schedule`` with its set given as ``table``, its context moved
    within each episode by ``changes`` (the core's, so every face changes it the same way)."""
    return ContextualEnv(env, schedule_provider(schedule, table), changes)


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


def program_key(selection_key: Hashable | None, *parts: Any) -> Hashable | None:
    """The :func:`shared_program` key of a selection and the other parts of a configuration, or None
    (a private program) where one of them cannot be hashed: a selector's closure, or a change holding
    a dict (its values or distributions)."""
    if selection_key is None:
        return None
    key = (*parts, selection_key)
    try:
        hash(key)
    except TypeError:
        return None
    return key


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


def state_packer(env: Env, schedule: ContextSchedule) -> Packer:
    """The packer of the contextual state: the carry every compiled program of ``env`` under
    ``schedule``, single or vector, reads and writes."""
    table = context_table(schedule)
    state, _ = jax.eval_shape(
        lambda key: contextual_env(env, schedule, table).reset(key), jax.random.key(0)
    )
    return Packer(state)


def observation_spaces(env: Env) -> tuple[gymnasium.spaces.Box, gymnasium.spaces.Box]:
    """A JAX env's gymnasium observation space (the original observation, then the context) and the
    space of its original part (flat)."""
    flat = env.observation_space.to_gymnasium()
    split = int(np.prod(env.base_observation_space.shape))
    return flat, gymnasium.spaces.Box(flat.low[:split], flat.high[:split], dtype=np.float32)


def action_check(space: gymnasium.spaces.Space, copies: int | None = None) -> Callable[[Any], Any]:
    """The one action rule of every gymnasium face (single and vector, compiled and host), as a function
    from a user's action to what the backend takes (an int, an int32 or float array).

    A discrete action is an integer in the space's range. A Box action is numbers of the space's shape,
    finite, clipped to the bounds (as gymnasium's MuJoCo and Box2D environments and the JAX core's
    transitions treat them). Other host spaces take what their ``contains`` accepts. Anything else is
    refused with a ValueError saying what an action must be. ``copies``: the vector env's leading axis.
    """
    rule = ActionRule(space, copies)
    if isinstance(space, gymnasium.spaces.Discrete):
        return rule.integer if copies is None else rule.integers
    return rule.box if isinstance(space, gymnasium.spaces.Box) else rule.contained


class ActionRule:
    """The checks of :func:`action_check`, one method per kind of space (bound once: a single step
    pays one call)."""

    def __init__(self, space: gymnasium.spaces.Space, copies: int | None):
        self.space = space
        self.batch = () if copies is None else (copies,)
        self.noun = "action" if copies is None else "actions"
        if isinstance(space, gymnasium.spaces.Discrete):
            self.low, self.high = int(space.start), int(space.start + space.n)
            count = "an integer" if copies is None else f"{copies} integers"
            self.expected = f"{count} in [{self.low}, {self.high})"
        elif isinstance(space, gymnasium.spaces.Box):
            self.low, self.high = space.low, space.high
            self.bounds = (space.low.ravel().tolist(), space.high.ravel().tolist())
            self.shape = (*self.batch, *space.shape)
            numbers = "a finite float array" if copies is None else "finite floats"
            self.expected = f"{numbers} of shape {self.shape}"
        else:
            self.expected = f"in the action space {space}"

    def refusal(self, action: Any) -> ValueError:
        return ValueError(f"{self.noun} must be {self.expected}, got {action!r}")

    def integer(self, action: Any) -> int:
        """One discrete action, as a Python int: no NumPy call."""
        if not isinstance(action, (bool, np.bool_)):
            try:
                index = operator.index(action)
            except TypeError:
                raise self.refusal(action) from None
            if self.low <= index < self.high:
                return index
        raise self.refusal(action)

    def integers(self, actions: Any) -> np.ndarray:
        values = _numbers(actions, "iu")
        if values is None or values.shape != self.batch:
            raise self.refusal(actions)
        if values.min() < self.low or values.max() >= self.high:
            raise self.refusal(actions)
        return values.astype(np.int32, copy=False)

    def box(self, action: Any) -> np.ndarray:
        values = _numbers(action, "iuf")
        if values is None or values.shape != self.shape:
            raise self.refusal(action)
        values = values.astype(self.space.dtype, copy=False)
        # One action inside the bounds, the common case, checked on Python floats.
        if not self.batch:
            inside = zip(values.ravel().tolist(), *self.bounds, strict=True)
            if all(low <= value <= high for value, low, high in inside):  # False for NaN
                return values
        if not np.isfinite(values).all():
            raise self.refusal(action)
        return np.minimum(np.maximum(values, self.low), self.high)

    def contained(self, action: Any) -> Any:
        if not self.space.contains(np.asarray(action, self.space.dtype)):
            raise self.refusal(action)
        return action


def _numbers(action: Any, kinds: str) -> np.ndarray | None:
    """``action`` as a NumPy array whose dtype is one of ``kinds`` (NumPy's kind letters), else None."""
    try:
        values = np.asarray(action)
    except (TypeError, ValueError):  # ragged lists
        return None
    return values if values.dtype.kind in kinds else None


def _floats(x: Any) -> jax.Array:
    """``x`` flat in float32, as the host reads observations and context vectors."""
    return jnp.ravel(jnp.asarray(x, jnp.float32))


class JaxPrograms:
    """One copy of the core contextual env, compiled: each call one uint32 vector in, one out
    (:class:`PackedProgram`).

    ``begin`` takes a :class:`Run`, ``restart`` the packed state; each returns :class:`Started`
    (``*_with`` also take the episode's :class:`Given` context). ``advance`` takes (packed state,
    action) and steps without a restart (a gymnasium single env restarts only when asked), returning
    :class:`Stepped`, with the step's context where ``changes`` move it (else None: no words).
    """

    def __init__(self, env: Env, schedule: ContextSchedule, changes: Change | None = None):
        self.env = env
        self.schedule = schedule
        self.changes = changes
        self.space = env.context_space
        self.packer = state_packer(env, schedule)
        table, carry = context_table(schedule), np.zeros(self.packer.size, np.uint32)
        run = Run(key_data(), np.uint32(0), np.uint32(0))
        given = Given(np.zeros(len(self.space), np.float32), np.int32(0))
        discrete = isinstance(env.action_space, Discrete)
        action = np.int32(0) if discrete else np.zeros(env.action_space.shape, np.float32)
        self.begin = PackedProgram(self._begin, run, table, jit=cpu_jit)
        self.begin_with = PackedProgram(self._begin_with, (run, given), table, jit=cpu_jit)
        self.restart = PackedProgram(self._restart, carry, table, jit=cpu_jit)
        self.restart_with = PackedProgram(self._restart_with, (carry, given), table, jit=cpu_jit)
        self.advance = PackedProgram(self._advance, (carry, action), jit=cpu_jit)

    def _cenv(self, table) -> ContextualEnv:
        return contextual_env(self.env, self.schedule, table, self.changes)

    def _started(self, state, timestep) -> Started:
        return Started(
            self.packer.pack(state),
            _floats(timestep.obs),
            _floats(self.space.to_array(state.context)),
            state.context_id,
            env_step_info(timestep),
        )

    def _begin(self, run: Run, table) -> Started:
        cenv = self._cenv(table)
        return self._started(*cenv.reset(run.key, run.episode, run.copies))

    def _begin_with(self, request: tuple[Run, Given], table) -> Started:
        (run, given), cenv = request, self._cenv(table)
        context = self.space.from_array(given.context)
        return self._started(
            *cenv.reset(run.key, run.episode, run.copies, context, given.context_id)
        )

    def _restart(self, carry, table) -> Started:
        cenv = self._cenv(table)
        return self._started(*cenv.restart(self.packer.unpack(carry)))

    def _restart_with(self, request: tuple[Any, Given], table) -> Started:
        (carry, given), cenv = request, self._cenv(table)
        context = self.space.from_array(given.context)
        return self._started(*cenv.restart(self.packer.unpack(carry), context, given.context_id))

    def _advance(self, request: tuple[Any, Any]) -> Stepped:
        carry, action = request
        cenv = ContextualEnv(self.env, self.schedule.provider, self.changes)
        state, timestep = cenv.advance(self.packer.unpack(carry), action)  # advancing never selects
        moved = None if self.changes is None else _floats(self.space.to_array(state.context))
        return Stepped(
            self.packer.pack(state),
            _floats(timestep.obs),
            jnp.asarray(timestep.reward, jnp.float32),
            timestep.terminated,
            timestep.truncated,
            env_step_info(timestep),
            moved,
        )


class JaxBackend:
    """A JAX ``Env`` stepped through :class:`JaxPrograms`; the host keeps the packed state. The time limit
    and the context observation are the core env's; the action rule is :func:`action_check`'s.
    ``context_vector`` is the context the last start or step ran under (``changes`` move it)."""

    def __init__(self, env: Env, schedule: ContextSchedule, changes: Change | None = None):
        self.programs = shared_program(
            program_key(schedule.selection_key, "single", env, changes),
            lambda: JaxPrograms(env, schedule, changes),
        )
        self.packer = self.programs.packer
        self.table = on_cpu(context_table(schedule))
        self.action_space = env.action_space.to_gymnasium()
        self.check = action_check(self.action_space)
        self.flat_space, self.base_space = observation_spaces(env)
        self.carry: np.ndarray | None = None
        self.context_vector: np.ndarray | None = None
        # The environment's facts of the last start or step (``Env.step_info``), for gymnasium's info.
        self._step_info: dict[str, Any] = {}
        # The step's input, filled in place through its fields: per-step host work is a few NumPy calls.
        self._advance = self.programs.advance
        self._request, (self._carry_in, self._action_in) = self._advance.inputs.zeros_host()
        self._stepped = self._advance.outputs.unpack_host

    # ---- host side ------------------------------------------------------------------------------------
    def _start(self, program: PackedProgram, request: Any) -> tuple[np.ndarray, np.ndarray, int]:
        started = program.outputs.unpack_host(
            program(program.inputs.pack_host(request), self.table)
        )
        self.carry = started.carry
        self._step_info = info_to_host(started.info)
        self.context_vector = started.context.copy()
        return started.obs.copy(), self.context_vector, int(started.context_id)

    def step_info(self) -> dict[str, Any]:
        """The environment's facts of the last start or step (``Env.step_info``)."""
        return self._step_info

    def begin(
        self, key_bits: np.ndarray, copy: int, num_copies: int, override=None, rng=None
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """A new run's first episode (global episode ``copy``): (observation, context vector, id).

        ``override``: (context vector, id) to run instead of the selector's choice. ``rng`` is for host
        simulators: every draw here comes from the key.
        """
        run = Run(key_bits, copy, num_copies)
        if override is None:
            return self._start(self.programs.begin, run)
        return self._start(self.programs.begin_with, (run, Given(*override)))

    def restart(self, override=None) -> tuple[np.ndarray, np.ndarray, int]:
        """The next episode of this copy (global episode + number of copies)."""
        if override is None:
            return self._start(self.programs.restart, self.carry)
        return self._start(self.programs.restart_with, (self.carry, Given(*override)))

    def advance(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        self._action_in[...] = self.check(action)
        self._carry_in[:] = self.carry
        stepped = self._stepped(self._advance(self._request))
        self.carry = stepped.carry
        if stepped.info:
            self._step_info = info_to_host(stepped.info)
        if stepped.context is not None:
            self.context_vector = stepped.context.copy()
        obs, reward = stepped.obs.copy(), float(stepped.reward)
        return obs, reward, bool(stepped.terminated), bool(stepped.truncated)

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


class ScalarPhysics:
    """A JAX ``Env``'s scalar physics as a host simulator, behind a ``HostEnv``'s calls.

    A compiled call costs about 15 µs on a CPU whatever it computes; the same physics on Python floats
    (the env's ``host_transition``, written once against an array namespace together with its JAX
    ``transition``, see ``contextrl.core.scalar``) costs a few. Each episode starts with the env's own
    ``init`` and ``observe`` (compiled into :class:`HostPrograms`' start program, which derives the
    episode's start key), so start states are the compiled path's; each step then runs in
    Python and rounds the state and reward to float32, as the compiled path holds them. The host computes
    in double precision, so trajectories agree with the compiled path's to float32 rounding, not bit for
    bit. Only deterministic steps run here (:func:`steps_on_host`).
    """

    def __init__(self, env: Env):
        self.env = env
        self.context_space = env.context_space
        self.action_space = env.action_space.to_gymnasium()
        self.base_observation_space = env.base_observation_space.to_gymnasium()
        self._discrete = isinstance(env.action_space, Discrete)
        self._names = self.context_space.names
        physics = jax.eval_shape(env.init, jax.random.key(0), env.default_context())
        if not isinstance(physics, jax.ShapeDtypeStruct) or physics.dtype != jnp.float32:
            raise TypeError(
                f"{env.name}'s host path needs its physics state to be one float32 array"
            )
        self._transition = env.host_transition
        self._observe = env.host_observe
        self.state: list[float] = []
        self.context: Any = None
        self._values: types.SimpleNamespace | None = None  # the context as Python floats

    def reset_physics(self, context: Any, started: HostStart) -> np.ndarray:
        """Start an episode under ``context`` from the start state and observation that
        :class:`HostPrograms` drew; the first observation."""
        if context is not self.context:
            values = [float(getattr(context, name)) for name in self._names]
            self._values = types.SimpleNamespace(**dict(zip(self._names, values, strict=True)))
            self.context = context
        self.state = started.state.tolist()
        return started.obs

    def step_physics(self, action: Any) -> tuple[list[float], float, bool]:
        """``(observation, reward, terminated)`` of one checked action, on Python floats."""
        action = action if self._discrete else action.ravel().tolist()
        state, reward, terminated = self._transition(self.state, action, self._values)
        rounded = np.array([*state, reward], np.float32).tolist()
        self.state = rounded[:-1]
        return self._observe(self.state, self._values), rounded[-1], bool(terminated)

    def step_info(self) -> dict[str, Any]:
        """No facts: an env that reports them steps in the compiled programs."""
        return {}

    def physics_and_context(self) -> tuple[Any, Any]:
        """The current physics state and context as NumPy values (for rendering)."""
        return np.asarray(self.state, np.float32), self.context

    def close(self) -> None:
        """Nothing to release."""


class HostPrograms:
    """The compiled part of a host episode: its start (the context, the start key, the first context
    observation and, for scalar physics, the start state) and the context observation of a later step.

    Shared by every host adapter with the same selection, context observation and physics
    (:func:`shared_program`): 64 host copies compile these once, not 64 times.
    """

    def __init__(self, schedule: ContextSchedule, obs_context: ContextObservation, physics: Any):
        self.schedule = schedule
        self.space = schedule.space
        self.obs_context = obs_context
        self.physics = physics  # the JAX env of scalar physics, or None for a HostEnv
        zero = np.int32(0)
        request = StartRequest(key_data(), zero, zero, zero, np.zeros(len(self.space), np.float32))
        self.start = PackedProgram(self._start, request, context_table(schedule), jit=cpu_jit)
        self.extra = cpu_jit(self._extra)

    def _extra(self, vector, start_key_bits, time):
        """The context observation at step ``time`` of an episode (noise drawn from its start key)."""
        key = jax.random.fold_in(jax.random.wrap_key_data(start_key_bits), time)
        return self.obs_context.values(self.space, self.space.from_array(vector), key)

    def _start(self, request: StartRequest, table) -> HostStart:
        """An episode's start: the context (the selector's or the one given), its start key, the first
        context observation and, for scalar physics, the start state and observation."""
        provider = schedule_provider(self.schedule, table)
        chosen, chosen_id, start_key = choose_context(provider, request.key, request.episode)
        given = request.given == 1
        vector = jnp.where(given, request.context, self.space.to_array(chosen))
        index = jnp.where(given, request.context_id, jnp.asarray(chosen_id, jnp.int32))
        bits = jax.random.key_data(start_key)
        hidden = self.obs_context.hidden
        extra = jnp.zeros(0, jnp.float32) if hidden else _floats(self._extra(vector, bits, 0))
        started = HostStart(_floats(vector), index, bits, extra)
        if self.physics is None:
            return started
        context = self.space.from_array(vector)  # the env's own start state and first observation
        state = self.physics.init(start_key, context)
        return started._replace(
            state=_floats(state), obs=_floats(self.physics.observe(state, context))
        )


class HostBackend:
    """A host simulator stepped from Python: a ``HostEnv``, or a JAX env's :class:`ScalarPhysics`.

    The simulator applies the context and steps; this backend owns the rest of the host path once: each
    episode's context (:func:`contextrl.core.choose_context`, the compiled path's selection code, with
    the same global episode index) and start key, the context observation, the time limit and the action
    rule. A ``HostEnv`` starts from the generator ``reset(seed=...)`` seeded, scalar physics from the
    episode's start key. An episode's start is one compiled call.
    """

    def __init__(
        self,
        simulator: Any,
        schedule: ContextSchedule,
        obs_context: ContextObservation,
        max_steps: int,
    ):
        self.simulator = simulator
        self.space = simulator.context_space
        self.obs_context = obs_context
        self.max_steps = max_steps
        self.action_space = simulator.action_space
        self.check = action_check(self.action_space)
        self.base_space = base = simulator.base_observation_space
        if obs_context.hidden:  # the original observation as it is (pixels keep shape and dtype)
            self.flat_space = base
        else:
            low, high = obs_context.bounds(self.space)
            self.flat_space = gymnasium.spaces.Box(
                np.concatenate([np.ravel(base.low), low]).astype(np.float32),
                np.concatenate([np.ravel(base.high), high]).astype(np.float32),
                dtype=np.float32,
            )
        self.table = on_cpu(context_table(schedule))
        self._keyed = isinstance(simulator, ScalarPhysics)
        physics = simulator.env if self._keyed else None
        key = schedule.selection_key
        programs = shared_program(
            None if key is None else ("host", key, obs_context, physics),
            lambda: HostPrograms(schedule, obs_context, physics),
        )
        self._start_program, self._extra = programs.start, programs.extra
        # The start program's input, filled in place through its fields.
        self._words, self._request = programs.start.inputs.zeros_host()
        self._members: dict[int, Any] = {}  # the context objects of the set's members, built once
        self.time = 0
        self.context: Any = None
        self._run: tuple[np.ndarray, int, int] | None = None  # key bits, episode, number of copies
        self._rng: np.random.Generator | None = None
        self._started: HostStart | None = None  # the episode's start: context vector, start key…
        self._fixed_extra: np.ndarray | None = None  # the context observation when it has no noise

    def _context(self, vector: np.ndarray, index: int) -> Any:
        """The episode's context object, built with NumPy (``from_array``'s JAX ops would cost
        milliseconds per reset on the host); a set member's once."""
        if index in self._members:
            return self._members[index]
        context = self.space.context_class(
            **{
                name: np.asarray(value, feature.dtype)
                for (name, feature), value in zip(self.space.features.items(), vector, strict=True)
            }
        )
        if index >= 0:
            self._members[index] = context
        return context

    def _observation(self, base_obs: Any, extra: np.ndarray) -> np.ndarray:
        if self.obs_context.hidden:
            return np.asarray(base_obs, self.flat_space.dtype)
        if isinstance(base_obs, list):  # scalar physics' Python floats: one conversion
            return np.array(base_obs + extra.tolist(), np.float32)
        return np.concatenate((np.ravel(base_obs), extra), dtype=np.float32)

    def _start(self, override) -> tuple[np.ndarray, np.ndarray, int]:
        key_bits, episode, _ = self._run
        request = self._request
        request.key[:], request.episode[...] = key_bits, episode
        request.given[...] = override is not None
        if override is not None:
            request.context[:], request.context_id[...] = override
        program = self._start_program
        started = program.outputs.unpack_host(program(self._words, self.table))
        self._started = started
        self._fixed_extra = started.extra if self.obs_context.noise == 0 else None
        index = int(started.context_id)
        self.context = self._context(started.context, index)
        self.time = 0
        # Where the start state comes from: scalar physics' compiled start, a HostEnv's generator.
        base_obs = self.simulator.reset_physics(self.context, started if self._keyed else self._rng)
        return self._observation(base_obs, started.extra), started.context, index

    def begin(self, key_bits, copy, num_copies, override=None, rng=None):
        """A new run's first episode (global episode ``copy``); ``rng`` seeds a ``HostEnv``'s starts."""
        self._run = (key_bits, int(copy), int(num_copies))
        self._rng = rng
        return self._start(override)

    def restart(self, override=None):
        key_bits, episode, num_copies = self._run
        self._run = (key_bits, episode + num_copies, num_copies)
        return self._start(override)

    def advance(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        base_obs, reward, terminated = self.simulator.step_physics(self.check(action))
        self.time += 1
        extra = self._fixed_extra
        if extra is None:  # a noisy context observation: drawn anew at every step
            time = np.uint32(self.time)
            started = self._started
            extra = np.asarray(self._extra(started.context, started.start_key, time))
        return (
            self._observation(base_obs, extra),
            float(reward),
            bool(terminated),
            self.time >= self.max_steps,
        )

    def step_info(self) -> dict[str, Any]:
        return self.simulator.step_info()

    def close(self) -> None:
        self.simulator.close()


def make_backend(
    env: Env | Any,
    schedule: ContextSchedule,
    obs_context: ContextObservation,
    max_steps: int,
    changes: Change | None = None,
) -> JaxBackend | HostBackend:
    """The backend of ``env`` (a JAX env carrying ``obs_context``, or a ``HostEnv``): compiled programs,
    or a host simulator (a ``HostEnv`` itself, or a JAX env's scalar physics where it offers them).
    ``changes`` (bound, JAX envs only) step in the compiled programs: the core's step applies them,
    which scalar physics would have to repeat."""
    if not isinstance(env, Env):
        return HostBackend(env, schedule, obs_context, max_steps)
    if changes is None and steps_on_host(env):
        return HostBackend(ScalarPhysics(env), schedule, obs_context, max_steps)
    return JaxBackend(env, schedule, changes)
