"""The vector gymnasium environment: N copies, each with its own context, stepped in one compiled call.

    envs = gymnasium.make_vec("contextrl/CartPole-v0", num_envs=64,
                              contexts=crl.sample(env, {"length": crl.Uniform(0.25, 1.0)}, 64, key))

Auto-reset is gymnasium's ``SAME_STEP`` mode (declared in ``metadata["autoreset_mode"]``): when a copy's
episode ends, the same ``step`` call returns the first observation of its next episode, and the last one
of the ended episode is in ``info["final_obs"][i]`` (``info["_final_obs"][i]`` is True). This is the
core's own convention, so no step is wasted on a reset. Copy ``i`` takes the context of global episode
``i + e × num_envs`` from the selector at its ``e``-th episode: with round robin over N contexts and N
copies, copy ``i`` always runs context ``i``. Host environments (CPU simulators) get the same interface
from worker processes that each step a slice of the copies (see :func:`make_vector_env`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from contextrl.context.changes import Change
from contextrl.context.schedule import RESAMPLED_ID, ContextSchedule
from contextrl.core.env import Env, tree_where
from contextrl.core.registry import spec
from contextrl.gymnasium.backends import (
    action_check,
    context_table,
    contextual_env,
    env_step_info,
    observation_spaces,
    program_key,
    shared_program,
    state_packer,
)
from contextrl.gymnasium.env import (
    ContextView,
    build_setup,
    check_count,
    observation_space,
    render_fps,
    reset_override,
    run_key_bits,
    split_observation,
)
from contextrl.gymnasium.frames import CopySteps, key_data
from contextrl.gymnasium.host_vector import HostVectorEnv
from contextrl.gymnasium.packing import Packer


class VectorPrograms:
    """The core's ``reset_copies`` and ``step_copies`` of ``num_envs`` copies, compiled.

    The state stays on the device as one uint32 array (a row per copy); each step takes it, the
    actions and the context set, and returns it with the copies' :class:`CopySteps`, packed by
    ``frame``. Programs are shared by equal configurations; the context set is an argument. ``changes``
    move each copy's context within its episode, in the core's step.
    """

    def __init__(
        self, env: Env, schedule: ContextSchedule, num_envs: int, changes: Change | None = None
    ):
        self.env = env
        self.schedule = schedule
        self.num_envs = num_envs
        self.changes = changes
        self.space = env.context_space
        self.packer = state_packer(env, schedule)
        vectors = np.zeros((num_envs, len(self.space)), np.float32)
        ids, given = np.zeros(num_envs, np.int32), np.zeros(num_envs, bool)
        examples = (key_data(), context_table(schedule), vectors, ids, given)
        _, steps = jax.eval_shape(self._start, *examples)
        self.frame = Packer.of_rows(steps)
        self.reset = jax.jit(self._packed(self._start))
        self.step = jax.jit(self._packed(self._advance), donate_argnums=0)

    def _packed(self, program: Callable) -> Callable:
        """``program`` returning the copies' state and steps as rows of uint32 words."""

        def packed(*args):
            state, steps = program(*args)
            return jax.vmap(self.packer.pack)(state), jax.vmap(self.frame.pack)(steps)

        return packed

    def _start(self, key_bits, table, override, override_id, given):
        """Every copy starts its first episode; where ``given``, under the ``override`` context."""
        cenv = contextual_env(self.env, self.schedule, table, self.changes)
        num_envs = self.num_envs

        def start(copy, vector, context_id, use_given):
            chosen = cenv.reset(key_bits, copy, num_envs)
            supplied = cenv.reset(
                key_bits, copy, num_envs, self.space.from_array(vector), context_id
            )
            return tree_where(use_given, supplied, chosen)

        copies = jnp.arange(num_envs, dtype=jnp.int32)
        state, timestep = jax.vmap(start)(copies, override, override_id, given)
        return state, self._steps(state, timestep)

    def _advance(self, carry, actions, table):
        cenv = contextual_env(self.env, self.schedule, table, self.changes)
        state = jax.vmap(self.packer.unpack)(carry)
        state, timestep = cenv.step_copies(state, actions)
        return state, self._steps(state, timestep)

    @property
    def _sends_context(self) -> bool:
        """Whether the host needs the copies' context values: drawn at reset, or moved by changes."""
        return self.schedule.resamples or self.changes is not None

    def _steps(self, state, timestep) -> CopySteps:
        def flat(x):
            return x.reshape(self.num_envs, -1).astype(jnp.float32)

        return CopySteps(
            flat(timestep.obs),
            timestep.reward.astype(jnp.float32),
            timestep.terminated,
            timestep.truncated,
            flat(timestep.final_obs),
            timestep.info["context_id"].astype(jnp.int32),
            state.context_id.astype(jnp.int32),
            jax.vmap(self.space.to_array)(state.context) if self._sends_context else None,
            env_step_info(timestep),
        )


class ContextualVectorEnv(gymnasium.vector.VectorEnv):
    """``num_envs`` copies of a JAX environment with per-copy contexts (arguments as the single env;
    with ``changes``, ``info["context"]`` holds each copy's value at this step)."""

    metadata = {
        "autoreset_mode": AutoresetMode.SAME_STEP,
        "render_modes": ["rgb_array"],
        "render_fps": 50,
    }

    def __init__(
        self,
        env_id: str | Env,
        num_envs: int = 1,
        contexts: Any = None,
        context_selector: str | Callable | None = None,
        obs_context_features: None | str | Sequence[str] = None,
        obs_context_as_dict: bool = False,
        obs_context_normalize: bool = False,
        obs_context_noise: float = 0.0,
        max_steps: int | None = None,
        render_mode: str | None = None,
        changes: Change | None = None,
        **env_kwargs: Any,
    ):
        check_count("num_envs", num_envs)
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        view = ContextView(
            obs_context_features, obs_context_as_dict, obs_context_normalize, obs_context_noise
        )
        made = build_setup(env_id, contexts, context_selector, view, max_steps, env_kwargs, changes)
        if not isinstance(made.env, Env):
            raise TypeError(f"{made.env.name} is a host environment; use make_vector_env for it")
        self.env, self.schedule, self.changes = made.env, made.schedule, made.changes
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self.obs_context_as_dict = obs_context_as_dict
        self.context_space = self.env.context_space
        self.metadata = {**self.metadata, "render_fps": render_fps(self.env)}
        self.single_action_space = self.env.action_space.to_gymnasium()
        self.check = action_check(self.single_action_space, self.num_envs)
        flat, base = observation_spaces(self.env)
        self.single_observation_space = observation_space(flat, base, obs_context_as_dict)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        ids = self.schedule.ids
        self._id_table = (
            np.asarray(ids, np.int64)
            if all(isinstance(i, (int, np.integer)) for i in ids)
            else np.asarray(ids, object)
        )
        self.programs = shared_program(
            program_key(
                self.schedule.selection_key, "vector", self.env, self.num_envs, self.changes
            ),
            lambda: VectorPrograms(self.env, self.schedule, self.num_envs, self.changes),
        )
        self.packer = self.programs.packer
        self._table_host = context_table(self.schedule)
        self.table = jnp.asarray(self._table_host)
        self._values = np.zeros((self.num_envs, len(self.context_space)), np.float32)
        self._ids_are_indices = self._id_table.dtype != object and np.array_equal(
            self._id_table, np.arange(len(self._id_table))
        )
        self._everyone = np.ones(self.num_envs, bool)
        self._everyone.setflags(write=False)  # shared by every info dict, so read-only
        self._choices = {
            name: np.asarray(f.choices, object)
            for name, f in self.context_space.features.items()
            if f.kind == "categorical"
        }
        self._carry: jax.Array | None = None  # stays on the device between steps
        # The last reset's or step's packed rows (a row per copy, laid out by ``programs.frame``),
        # on the device: what the torch face views without a copy.
        self.rows: jax.Array | None = None

    # ---- host side ------------------------------------------------------------------------------------
    def _user_ids(self, indices: np.ndarray) -> np.ndarray:
        indices = indices.astype(np.int64)
        if self._ids_are_indices:  # ids 0..K-1 (and -1 for resampled): the index is the id
            return indices
        ids = self._id_table[np.maximum(indices, 0)]  # fancy indexing copies
        ids[indices < 0] = RESAMPLED_ID
        return ids

    def _observations(self, flat: np.ndarray):
        if not self.obs_context_as_dict:
            return flat
        return split_observation(flat, self.single_observation_space)

    def _context_info(self) -> dict[str, Any]:
        """Feature name → one value per copy (columns of the kept values: work per feature)."""
        info: dict[str, Any] = {}
        for column, (name, feature) in enumerate(self.context_space.features.items()):
            value = self._values[:, column]
            if feature.kind == "categorical":
                value = self._choices[name][value.astype(np.int64)]
            elif feature.kind == "int":
                value = value.astype(np.int64)
            info[name] = value
            info[f"_{name}"] = self._everyone
        return info

    def _update_values(self, steps: CopySteps, changed: np.ndarray) -> None:
        """The context values of the copies whose episode (or, with changes, context) changed: from
        the set, or as they came back."""
        if steps.context is not None:
            fresh = steps.context
        else:
            fresh = self._table_host[steps.context_id]
        self._values = np.where(changed[:, None], fresh, self._values)

    def _step_info(self, steps: CopySteps) -> dict[str, Any]:
        """The environment's facts of the step per copy (``Env.step_info``: completed, died…)."""
        info: dict[str, Any] = {}
        for name, values in steps.info.items():
            integer = np.issubdtype(values.dtype, np.integer)
            info[name] = values.astype(np.int64) if integer else values
            info[f"_{name}"] = self._everyone
        return info

    def _info(self, steps: CopySteps) -> dict[str, Any]:
        return {
            "context_id": self._user_ids(steps.context_id),
            "_context_id": self._everyone,
            "context": self._context_info(),
            "_context": self._everyone,
            **self._step_info(steps),
        }

    def _overrides(self, options: dict[str, Any] | None):
        """Per-copy contexts asked for by ``reset(options=...)``: (vectors, set indices, given mask).

        ``options["context"]`` is one context for every copy or a list with one per copy (None: the
        selector's choice); ``options["context_id"]`` likewise with ids of the context set.
        """
        count, features = self.num_envs, len(self.context_space)
        vectors = np.zeros((count, features), np.float32)
        indices = np.full(count, -1, np.int32)
        given = np.zeros(count, bool)
        if not options:
            return vectors, indices, given
        unknown = set(options) - {"context", "context_id"}
        if unknown:
            raise ValueError(
                f"unknown reset options {sorted(unknown)}; use 'context' or 'context_id'"
            )
        if len(options) > 1:
            raise ValueError("give either options['context'] or options['context_id'], not both")
        ((name, value),) = options.items()
        per_copy = isinstance(value, (list, tuple))
        if per_copy and len(value) != count:
            raise ValueError(
                f"options[{name!r}] lists {len(value)} entries; give one per copy ({count}) "
                "or one for all"
            )
        for copy, entry in enumerate(value if per_copy else [value] * count):
            if entry is not None:
                vectors[copy], indices[copy] = reset_override(self.schedule, {name: entry})
                given[copy] = True
        return vectors, indices, given

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Start every copy's first episode; ``options`` may set contexts (see :meth:`_overrides`)."""
        vectors, indices, given = self._overrides(options)
        if isinstance(seed, (list, tuple)):
            seed = seed[0]
        super().reset(seed=seed)
        key_bits = run_key_bits(self.np_random)
        self._carry, self.rows = self.programs.reset(key_bits, self.table, vectors, indices, given)
        steps = self.programs.frame.unpack_host(np.asarray(self.rows))
        self._values = vectors  # the given ones; the others from the set or the steps
        self._update_values(steps, ~given)
        return self._observations(steps.obs), self._info(steps)

    def step(self, actions):
        if self._carry is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        return self.step_checked(self.check(actions))

    def step_checked(self, actions: jax.Array):
        """:meth:`step` for actions already checked and placed as the program takes them (an array of
        the action space's dtype, one row per copy): the torch face's, which checks tensors itself."""
        if self._carry is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        self._carry, self.rows = self.programs.step(self._carry, actions, self.table)
        steps = self.programs.frame.unpack_host(np.asarray(self.rows))
        done = steps.terminated | steps.truncated
        changed = done if self.changes is None else self._everyone
        if changed.any():
            self._update_values(steps, changed)
        info = self._info(steps)
        if done.any():
            info["final_obs"] = self._observations(steps.final_obs)
            info["_final_obs"] = done
            # The step facts are the ended episode's (taken before the restart), as in ``info``.
            facts = self._step_info(steps)
            info["final_info"] = {
                "context_id": self._user_ids(steps.final_context_id),
                "_context_id": done,
                **{name: done if name.startswith("_") else value for name, value in facts.items()},
            }
            info["_final_info"] = done
        obs = self._observations(steps.obs)
        return obs, steps.reward, steps.terminated, steps.truncated, info

    def render(self):
        if self.render_mode is None or self._carry is None:
            return None
        from contextrl.render import draw

        frames = []
        for words in np.asarray(self._carry):
            state = self.packer.unpack_host(words)
            frames.append(draw(self.env, state.env_state.physics, state.context))
        return tuple(frames)


def make_vector_env(
    env_id: str,
    num_envs: int = 1,
    vectorization: str = "async",
    max_episode_steps: int | None = None,
    num_workers: int | None = None,
    **kwargs: Any,
) -> gymnasium.vector.VectorEnv:
    """A vector env for any registered id: one compiled call for JAX envs, worker processes for host
    envs.

    Host copies are stepped in slices by :class:`~contextrl.gymnasium.host_vector.HostVectorEnv`:
    ``vectorization="async"`` here and in ``num_workers`` worker processes (None: a slice per
    available core while each keeps 8 copies), ``"sync"`` all here; copy ``i`` takes the set's
    contexts as described above, with the same ``SAME_STEP`` auto-reset. ``max_episode_steps`` is
    accepted for ``gymnasium.make_vec`` and becomes ``max_steps`` when given.
    """
    if max_episode_steps is not None:
        kwargs.setdefault("max_steps", max_episode_steps)
    if vectorization not in ("async", "sync"):
        raise ValueError(f"vectorization must be 'async' or 'sync', got {vectorization!r}")
    if not spec(env_id).runs_on_host(kwargs):
        if num_workers is not None:
            raise ValueError(
                f"{env_id} steps its copies in one compiled call; num_workers is for "
                "host environments"
            )
        return ContextualVectorEnv(env_id, num_envs, **kwargs)
    if vectorization == "sync":
        if num_workers not in (None, 0):
            raise ValueError(
                f'vectorization="sync" steps in this process; got num_workers={num_workers}'
            )
        num_workers = 0
    return HostVectorEnv(env_id, num_envs, num_workers=num_workers, **kwargs)


__all__ = ["ContextualVectorEnv", "make_vector_env"]
