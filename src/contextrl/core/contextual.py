"""The one contextual stepping path: which context an episode gets, and how episodes end and restart.

``ContextualEnv`` pairs an environment with a provider (a context set and a selector, or a distribution
to resample from). Every face sits on it: hand-written ``jax.vmap`` loops, the gymnasium single and
vector environments, the agents' training loops; host simulators call its :func:`choose_context`.

Copy ``i`` of ``N`` runs the global episodes ``i, i + N, i + 2N, …``; the selector sees that global
index. All randomness comes from the key given to ``reset`` (one key for every copy: the global episode
index tells the copies apart), so the same seed and actions give the same trajectory through every face::

    cenv = crl.with_contexts(env, contexts)
    state, ts = cenv.reset_copies(key, 1024)        # = jax.vmap(cenv.reset, (None, 0, None))(key, arange, N)
    state, ts = jax.jit(cenv.step_copies)(state, actions)   # = jax.vmap(cenv.step)(state, actions)

Episode ``g``'s key is ``fold_in(key, g)``; its start draws (selection, start state) come from that key
and step ``t``'s draws from ``fold_in(episode_key, 2**32 - t)`` (counters no start draw reaches), so a
copy needs no key split per step, and a deterministic environment draws nothing between resets.

``changes`` (:mod:`contextrl.context.changes`) moves the context within an episode: step ``t`` runs
under ``changes.apply(key, t, context)`` and the state keeps that context, so every face and every
context observation sees the current value. Its draws come from ``fold_in(step key, 2**32 - 1)``, so
the environment's own draws are those of the same run without changes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from contextrl.context.changes import Change, bind
from contextrl.context.features import ContextError
from contextrl.context.schedule import resolve_contexts
from contextrl.context.selectors import Provider
from contextrl.core.env import Env, EnvState, TimeStep, tree_where

# step_copies restarts at most this share of the copies by gathering them; more take the full path.
RESTART_SHARE = 16
# Below this many copies, gathering costs more than restarting every copy (measured on a CPU).
GATHER_FROM = 1024


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ContextualState:
    """The inner environment state, the episode's context and id, and where the copy is in its run.

    ``episode`` is the global episode index (``copy + e * num_copies``); ``key`` is the run's key data.
    """

    env_state: EnvState
    context: Any
    context_id: jax.Array
    episode: jax.Array
    num_copies: jax.Array
    key: jax.Array


def key_bits(key) -> jax.Array:
    """The uint32 data of a typed key (``jax.random.key``) or of a raw ``PRNGKey``."""
    if jnp.issubdtype(jnp.asarray(key).dtype, jax.dtypes.prng_key):
        return jax.random.key_data(key)
    return jnp.asarray(key, jnp.uint32)


def episode_key(run_key_bits, episode) -> jax.Array:
    """The key of global episode ``episode`` of a run."""
    return jax.random.fold_in(jax.random.wrap_key_data(run_key_bits), episode)


def choose_context(provider: Provider, run_key_bits, episode) -> tuple[Any, jax.Array, jax.Array]:
    """``(context, context id, start key)`` of global episode ``episode``: the one selection code.

    Pure and jittable. The start key is what is left for the environment's start state (JAX ``reset``
    or a host simulator's seed).
    """
    start_key = episode_key(run_key_bits, episode)
    if not provider.uses_key:  # round robin and static: no random draw
        return (*provider(None, episode), start_key)
    select_key, start_key = jax.random.split(start_key)
    context, context_id = provider(select_key, episode)
    return context, context_id, start_key


@dataclasses.dataclass(frozen=True)
class ContextualEnv:
    """``env`` with a provider that picks the context of each new episode, and optionally
    ``changes`` that move it within the episode."""

    env: Env
    provider: Provider
    changes: Change | None = None

    def __post_init__(self):
        if self.provider.space is not self.env.context_space:
            raise ContextError(
                f"the contexts belong to {self.provider.space.context_class.__name__}, "
                f"but {self.env.name} uses {self.env.context_type.__name__}"
            )
        if self.changes is not None:
            object.__setattr__(self, "changes", bind(self.env, self.changes))

    @property
    def observation_space(self):
        return self.env.observation_space

    @property
    def action_space(self):
        return self.env.action_space

    def _begin(self, run_key_bits, episode, num_copies, context=None, context_id=-1):
        chosen, chosen_id, start_key = choose_context(self.provider, run_key_bits, episode)
        if context is not None:  # a context given for this episode (gymnasium reset options)
            chosen, chosen_id = context, context_id
        env_state, timestep = self.env.reset(start_key, chosen)
        state = ContextualState(
            env_state,
            chosen,
            jnp.asarray(chosen_id, jnp.int32),
            jnp.asarray(episode, jnp.int32),
            jnp.asarray(num_copies, jnp.int32),
            jnp.asarray(run_key_bits, jnp.uint32),
        )
        info = {
            **timestep.info,
            "context_id": state.context_id,
            "next_context_id": state.context_id,
        }
        return state, dataclasses.replace(timestep, info=info)

    def reset(
        self, key, copy=0, num_copies=1, context=None, context_id=-1
    ) -> tuple[ContextualState, TimeStep]:
        """Copy ``copy`` of ``num_copies`` starts its first episode (global episode ``copy``).

        ``context`` (with its ``context_id``, -1 by default) replaces the selector's choice.
        """
        return self._begin(key_bits(key), copy, num_copies, context, context_id)

    def restart(
        self, state: ContextualState, context=None, context_id=-1
    ) -> tuple[ContextualState, TimeStep]:
        """The copy's next episode (global index + ``num_copies``); ``context`` as in :meth:`reset`."""
        if context is None:
            return self._next_episode(state.key, state.episode, state.num_copies)
        return self._begin(
            state.key, state.episode + state.num_copies, state.num_copies, context, context_id
        )

    def advance(self, state: ContextualState, action) -> tuple[ContextualState, TimeStep]:
        """One step of the current episode (under its changed context), without restarting it."""
        changes_need_key = self.changes is not None and self.changes.uses_key
        step_key = None
        if self.env.steps_need_key or changes_need_key:
            episode = episode_key(state.key, state.episode)
            step = jnp.asarray(state.env_state.time + 1, jnp.uint32)
            step_key = jax.random.fold_in(episode, jnp.uint32(0) - step)  # 2**32 - t
        context = state.context
        if self.changes is not None:
            change_key = jax.random.fold_in(step_key, 2**32 - 1) if changes_need_key else None
            context = self.changes.apply(change_key, state.env_state.time + 1, context)
        env_key = step_key if self.env.steps_need_key else None
        env_state, timestep = self.env.advance(env_key, state.env_state, action, context)
        info = {
            **timestep.info,
            "context_id": state.context_id,
            "next_context_id": state.context_id,
        }
        return dataclasses.replace(
            state, env_state=env_state, context=context
        ), dataclasses.replace(timestep, info=info)

    @staticmethod
    def _settle(done, advanced, timestep, restarted, start) -> tuple[ContextualState, TimeStep]:
        """Same-step auto-reset: where ``done``, the restarted state and its first observation."""
        state = tree_where(done, restarted, advanced)
        info = {
            **timestep.info,
            "context_id": advanced.context_id,
            "next_context_id": state.context_id,
        }
        obs = jnp.where(done, start.obs, timestep.obs)
        return state, dataclasses.replace(timestep, obs=obs, info=info)

    def step(self, state: ContextualState, action) -> tuple[ContextualState, TimeStep]:
        """One step; when the episode ends the next context is chosen and the episode restarts."""
        advanced, timestep = self.advance(state, action)
        restarted, start = self.restart(advanced)
        return self._settle(timestep.done, advanced, timestep, restarted, start)

    # ---- batches of copies ---------------------------------------------------------------------------
    def reset_copies(self, key, num_copies: int) -> tuple[ContextualState, TimeStep]:
        """``num_copies`` copies (a leading axis), copy ``i`` starting global episode ``i``."""
        copies = jnp.arange(num_copies, dtype=jnp.int32)
        return jax.vmap(self.reset, in_axes=(None, 0, None))(key, copies, num_copies)

    def step_copies(self, state: ContextualState, action) -> tuple[ContextualState, TimeStep]:
        """``jax.vmap(self.step)``, drawing new episodes only for the copies whose episode ended.

        A restart depends only on the copy's run key and episode index, so when at most one copy in
        :data:`RESTART_SHARE` ends, only those are restarted (gathered, then written back); a step where
        more end restarts every copy, as does every step of fewer than :data:`GATHER_FROM` copies.
        Either way the result is ``jax.vmap(self.step)``'s.
        """
        advanced, timestep = jax.vmap(self.advance)(state, action)
        done = timestep.done
        num_copies = done.shape[0]
        room = num_copies // RESTART_SHARE

        def restart_all():
            restarted, start = jax.vmap(self.restart)(advanced)
            return jax.vmap(tree_where)(done, (restarted, start.obs), (advanced, timestep.obs))

        def restart_ended():
            (ended,) = jnp.nonzero(done, size=room, fill_value=num_copies)
            picked = jax.tree_util.tree_map(
                lambda leaf: jnp.take(leaf, ended, axis=0, mode="clip"),
                (advanced.key, advanced.episode, advanced.num_copies),
            )
            fresh = jax.vmap(self._next_episode)(*picked)
            return jax.tree_util.tree_map(
                lambda old, new: old.at[ended].set(new, mode="drop"),
                (advanced, timestep.obs),
                (fresh[0], fresh[1].obs),
            )

        if num_copies < GATHER_FROM:
            new_state, obs = restart_all()
        else:
            new_state, obs = jax.lax.cond(done.sum() <= room, restart_ended, restart_all)
        info = {
            **timestep.info,
            "context_id": advanced.context_id,
            "next_context_id": new_state.context_id,
        }
        return new_state, dataclasses.replace(timestep, obs=obs, info=info)

    def _next_episode(self, run_key_bits, episode, num_copies):
        return self._begin(run_key_bits, episode + num_copies, num_copies)


def make_provider(env: Env, contexts: Any, selector: str | Callable | None = None) -> Provider:
    """The provider of ``contexts`` in any form :func:`contextrl.context.resolve_contexts` accepts."""
    return resolve_contexts(env.context_space, contexts, selector).provider


def with_contexts(
    env: Env,
    contexts: Any,
    selector: str | Callable | None = None,
    changes: Change | None = None,
) -> ContextualEnv:
    """``env`` whose every episode takes its context from ``contexts`` (see :func:`make_provider`).

    ``selector``: "round_robin" (the default), "random", "static" or ``fn(key, episode, n) -> index``.
    ``changes``: how the context moves within an episode (:mod:`contextrl.context.changes`).
    """
    return ContextualEnv(env, make_provider(env, contexts, selector), changes)
