"""The vector gymnasium environment: N copies, each with its own context, stepped in one compiled call.

    envs = gymnasium.make_vec("contextrl/CartPole-v0", num_envs=64,
                              contexts=crl.sample(env, {"length": crl.Uniform(0.25, 1.0)}, 64, key))

Auto-reset is gymnasium's ``SAME_STEP`` mode (declared in ``metadata["autoreset_mode"]``): when a copy's
episode ends, the same ``step`` call returns the first observation of its next episode, and the last one
of the ended episode is in ``info["final_obs"][i]`` (``info["_final_obs"][i]`` is True). This is the
core's own convention, so no step is wasted on a reset. Copy ``i`` takes the context of global episode
``i + e × num_envs`` from the selector at its ``e``-th episode: with round robin over N contexts and N
copies, copy ``i`` always runs context ``i``. Host environments (CPU simulators) get the same interface
from gymnasium's ``AsyncVectorEnv`` of single adapters (see :func:`make_vector_env`).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from contextrl.context.features import ContextError
from contextrl.core.env import Env
from contextrl.core.registry import spec
from contextrl.core.spaces import Discrete
from contextrl.gymnasium.backends import advance, shared_program
from contextrl.gymnasium.env import ContextualGymEnv, build_env, check_max_steps, render_fps
from contextrl.gymnasium.packing import Packer
from contextrl.gymnasium.schedule import RESAMPLED_ID, ContextSchedule, resolve_contexts


class VectorPrograms:
    """The compiled reset and step of ``num_envs`` copies (vmapped), shared by equal configurations."""

    def __init__(self, env: Env, schedule: ContextSchedule, num_envs: int):
        self.env = env
        self.schedule = schedule
        self.num_envs = num_envs
        self.context_space = env.context_space
        self.discrete = isinstance(env.action_space, Discrete)
        key = jax.random.key(0)
        state = jax.eval_shape(lambda k, c: env.reset(k, c)[0], key, env.default_context())
        self.packer = Packer(
            (state, env.default_context(), jnp.int32(0), jnp.int32(0), jax.random.key_data(key))
        )
        self.reset = jax.jit(jax.vmap(self._reset_copy, in_axes=(None, 0, None)))
        self.step = jax.jit(self._step)

    def _global_episode(self, copy, episode):
        return copy.astype(jnp.int32) + episode * self.num_envs

    def _choose(self, select_key, copy, episode, table):
        vector, index = self.schedule.choose(select_key, self._global_episode(copy, episode), table)
        return self.context_space.from_array(vector), index

    def _restart_copy(self, key_bits, copy, episode, table):
        """A copy's next episode: split its key chain, pick the context, reset."""
        key, select_key, env_key = jax.random.split(jax.random.wrap_key_data(key_bits), 3)
        context, index = self._choose(select_key, copy, episode, table)
        state, timestep = self.env.reset(env_key, context)
        return state, timestep.obs, context, index, jax.random.key_data(key)

    def _reset_copy(self, seed_bits, copy, table):
        copy_key = jax.random.fold_in(jax.random.wrap_key_data(seed_bits), copy)
        episode = jnp.int32(0)
        state, obs, context, index, key_bits = self._restart_copy(
            jax.random.key_data(copy_key), copy, episode, table
        )
        carry = self.packer.pack((state, context, index, episode, key_bits))
        row = self._row(obs, jnp.float32(0), False, False, obs, index, index, context)
        return carry, row

    def _step(self, carry, action_words, copies, table):
        """All copies advance; only if some episode ended are the restarts computed (one cond).

        Same-step auto-reset as ``Env.step_then_reset``, but the reset (random start states, context
        choice) runs only on steps where an episode ends, which is most of the cost for few copies.
        """
        state, context, index, episode, key_bits = jax.vmap(self.packer.unpack)(carry)
        if self.discrete:
            action = jax.lax.bitcast_convert_type(action_words[:, 0], jnp.int32)
        else:
            action = jax.lax.bitcast_convert_type(action_words, jnp.float32).reshape(
                (carry.shape[0], *self.env.action_space.shape)
            )
        keys = jax.vmap(jax.random.wrap_key_data)(key_bits)
        state, final_obs, reward, terminated, truncated = jax.vmap(
            functools.partial(advance, self.env)
        )(keys, state, action, context)
        done = terminated | truncated
        restart = jax.lax.cond(
            done.any(),
            lambda: jax.vmap(self._restart_copy, in_axes=(0, 0, 0, None))(
                key_bits, copies, episode + 1, table
            ),
            lambda: (state, final_obs, context, index, key_bits),
        )
        kept = (state, final_obs, context, index, key_bits)
        state, obs, new_context, new_index, key_bits = jax.tree_util.tree_map(
            lambda fresh, old: jnp.where(done.reshape(-1, *([1] * (old.ndim - 1))), fresh, old),
            restart,
            kept,
        )
        new_episode = jnp.where(done, episode + 1, episode)
        carry = jax.vmap(self.packer.pack)((state, new_context, new_index, new_episode, key_bits))
        rows = jax.vmap(self._row)(
            obs, reward, terminated, truncated, final_obs, index, new_index, new_context
        )
        return carry, rows

    def _row(self, obs, reward, terminated, truncated, final_obs, index, new_index, context):
        """One float32 row per copy: obs, reward, flags, final_obs, ids, context values."""
        return jnp.concatenate(
            [
                obs,
                jnp.asarray(reward, jnp.float32)[None],
                jnp.asarray(terminated, jnp.float32)[None],
                jnp.asarray(truncated, jnp.float32)[None],
                final_obs,
                jnp.stack([index, new_index]).astype(jnp.float32),
                self.context_space.to_array(context),
            ]
        )


class ContextualVectorEnv(gymnasium.vector.VectorEnv):
    """``num_envs`` copies of a JAX environment with per-copy contexts (arguments as the single env)."""

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
        **env_kwargs: Any,
    ):
        if (
            isinstance(num_envs, bool)
            or not isinstance(num_envs, (int, np.integer))
            or num_envs < 1
        ):
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        check_max_steps(max_steps)
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if not isinstance(obs_context_as_dict, bool):
            raise ContextError(
                f"obs_context_as_dict must be True or False, got {obs_context_as_dict!r}"
            )
        env = build_env(env_id, max_steps, env_kwargs)
        if not isinstance(env, Env):
            raise TypeError(f"{env.name} is a host environment; use make_vector_env for it")
        self.schedule = resolve_contexts(env.context_space, contexts, context_selector)
        obs_context = self.schedule.observation(
            obs_context_features, obs_context_normalize, obs_context_noise
        )
        if obs_context_as_dict and obs_context.hidden:
            raise ContextError(
                "obs_context_as_dict=True needs visible context features; set "
                'obs_context_features to "all", "varying" or a list of names'
            )
        self.env = dataclasses.replace(env, obs_context=obs_context)
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self.obs_context_as_dict = obs_context_as_dict
        self.context_space = env.context_space
        self.metadata = {**self.metadata, "render_fps": render_fps(env)}
        self.single_action_space = self.env.action_space.to_gymnasium()
        self._discrete = isinstance(self.single_action_space, gymnasium.spaces.Discrete)
        flat = self.env.observation_space.to_gymnasium()
        self.base_size = int(np.prod(self.env.base_observation_space.shape))
        self.obs_size = flat.shape[0]
        if obs_context_as_dict:
            split = self.base_size
            self.single_observation_space = gymnasium.spaces.Dict(
                {
                    "obs": gymnasium.spaces.Box(flat.low[:split], flat.high[:split], np.float32),
                    "context": gymnasium.spaces.Box(
                        flat.low[split:], flat.high[split:], np.float32
                    ),
                }
            )
        else:
            self.single_observation_space = flat
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        ids = self.schedule.ids
        self._id_table = (
            np.asarray(ids, np.int64)
            if all(isinstance(i, (int, np.integer)) for i in ids)
            else np.asarray(ids, object)
        )
        program_key = self.schedule.program_key
        self.programs = shared_program(
            None if program_key is None else ("vector", self.env, program_key, self.num_envs),
            lambda: VectorPrograms(self.env, self.schedule, self.num_envs),
        )
        self.packer = self.programs.packer
        self.table = jnp.asarray(self.schedule.table)
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
        self._copies = jnp.arange(self.num_envs, dtype=jnp.uint32)
        self._carry: jax.Array | None = None  # stays on the device between steps

    # ---- host side ------------------------------------------------------------------------------------
    def _user_ids(self, indices: np.ndarray) -> np.ndarray:
        indices = indices.astype(np.int64)  # exact: indices are small integers stored as float32
        if self._ids_are_indices:  # ids 0..K-1 (and -1 for resampled): the index is the id
            return indices
        ids = self._id_table[np.maximum(indices, 0)]  # fancy indexing copies
        ids[indices < 0] = RESAMPLED_ID
        return ids

    def _observations(self, flat: np.ndarray):
        if not self.obs_context_as_dict:
            return flat
        return {"obs": flat[:, : self.base_size], "context": flat[:, self.base_size :]}

    def _context_info(self, rows: np.ndarray) -> dict[str, Any]:
        start = 2 * self.obs_size + 5
        info: dict[str, Any] = {}
        for column, (name, feature) in enumerate(self.context_space.features.items()):
            value = rows[:, start + column]
            if feature.kind == "categorical":
                value = self._choices[name][value.astype(np.int64)]
            elif feature.kind == "int":
                value = value.astype(np.int64)
            info[name] = value
            info[f"_{name}"] = self._everyone
        return info

    def _info(self, rows: np.ndarray) -> dict[str, Any]:
        ids_at = 2 * self.obs_size + 3
        return {
            "context_id": self._user_ids(rows[:, ids_at + 1]),
            "_context_id": self._everyone,
            "context": self._context_info(rows),
            "_context": self._everyone,
        }

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        if options:
            raise ValueError(f"unsupported reset options {sorted(options)}")
        if isinstance(seed, (list, tuple)):
            seed = seed[0]
        super().reset(seed=seed)
        seed_key = jax.random.key(int(self.np_random.integers(2**32, dtype=np.uint64)))
        seed_bits = np.asarray(jax.random.key_data(seed_key), np.uint32)
        self._carry, rows = self.programs.reset(seed_bits, self._copies, self.table)
        rows = np.asarray(rows)
        return self._observations(rows[:, : self.obs_size].copy()), self._info(rows)

    def _action_words(self, actions) -> np.ndarray:
        if self._discrete:
            actions = np.asarray(actions)
            if actions.shape != (self.num_envs,) or actions.dtype.kind not in "iu":
                raise ValueError(
                    f"actions must be {self.num_envs} integers in [0, {self.single_action_space.n}), "
                    f"got {actions!r}"
                )
            if actions.astype(np.uint64).max() >= self.single_action_space.n:  # negatives wrap
                raise ValueError(
                    f"actions must lie in [0, {self.single_action_space.n}), got {actions!r}"
                )
            return actions.astype(np.int32).view(np.uint32)[:, None]
        values = np.asarray(actions, np.float32)
        expected = (self.num_envs, *self.single_action_space.shape)
        if values.shape != expected or not np.all(np.isfinite(values)):
            raise ValueError(f"actions must be finite floats of shape {expected}, got {actions!r}")
        return values.reshape(self.num_envs, -1).view(np.uint32)

    def step(self, actions):
        if self._carry is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        self._carry, rows = self.programs.step(
            self._carry, self._action_words(actions), self._copies, self.table
        )
        rows = np.asarray(rows)
        d = self.obs_size
        obs = rows[:, :d].copy()
        reward = rows[:, d].copy()
        terminated = rows[:, d + 1] > 0.5
        truncated = rows[:, d + 2] > 0.5
        info = self._info(rows)
        done = terminated | truncated
        if done.any():
            final_obs = np.full(self.num_envs, None, object)
            ended = np.flatnonzero(done)
            finals = self._observations(rows[ended, d + 3 : 2 * d + 3].copy())
            for position, copy in enumerate(ended):
                final_obs[copy] = (
                    {k: v[position] for k, v in finals.items()}
                    if isinstance(finals, dict)
                    else finals[position]
                )
            info["final_obs"] = final_obs
            info["_final_obs"] = done
            info["final_info"] = {
                "context_id": self._user_ids(rows[:, 2 * d + 3]),
                "_context_id": done,
            }
            info["_final_info"] = done
        return self._observations(obs), reward, terminated, truncated, info

    def render(self):
        if self.render_mode is None or self._carry is None:
            return None
        from contextrl.render import draw

        frames = []
        for words in np.asarray(self._carry):
            state, context, *_ = self.packer.unpack_host(words)
            frames.append(draw(self.env, state.physics, context))
        return tuple(frames)


def make_vector_env(
    env_id: str,
    num_envs: int = 1,
    vectorization: str = "async",
    max_episode_steps: int | None = None,
    **kwargs: Any,
) -> gymnasium.vector.VectorEnv:
    """A vector env for any registered id: one compiled call for JAX envs, processes for host envs.

    Host copies are single adapters in gymnasium's ``AsyncVectorEnv`` (or ``SyncVectorEnv`` with
    ``vectorization="sync"``), copy ``i`` taking the set's contexts as described above, with the same
    ``SAME_STEP`` auto-reset. ``max_episode_steps`` is accepted for ``gymnasium.make_vec`` and becomes
    ``max_steps`` when given.
    """
    if max_episode_steps is not None:
        kwargs.setdefault("max_steps", max_episode_steps)
    if not spec(env_id).host:
        return ContextualVectorEnv(env_id, num_envs, **kwargs)
    if vectorization not in ("async", "sync"):
        raise ValueError(f"vectorization must be 'async' or 'sync', got {vectorization!r}")
    if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
        raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
    ContextualGymEnv(env_id, **kwargs).close()  # validate every argument here, not in N workers
    factories = [
        functools.partial(ContextualGymEnv, env_id, copy_index=i, num_copies=num_envs, **kwargs)
        for i in range(num_envs)
    ]
    if vectorization == "sync":
        return gymnasium.vector.SyncVectorEnv(factories, autoreset_mode=AutoresetMode.SAME_STEP)
    # "spawn": JAX is multithreaded, so forking a process that has used it can deadlock.
    return gymnasium.vector.AsyncVectorEnv(
        factories, autoreset_mode=AutoresetMode.SAME_STEP, context="spawn"
    )


__all__ = ["ContextualVectorEnv", "make_vector_env"]
