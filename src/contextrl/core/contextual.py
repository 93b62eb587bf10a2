"""An environment whose context is chosen at every reset, inside the compiled loop.

``ContextualEnv`` pairs an environment with a provider (a context set and a selector, or a distribution
to resample from). Its state carries the current context, its id and the episode index, so
``reset(key)`` and ``step(key, state, action)`` need no context argument and vmap over thousands of copies,
each following its own schedule.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import jax
import jax.numpy as jnp

from contextrl.context.distributions import DISTRIBUTIONS
from contextrl.context.features import ContextBase, ContextError
from contextrl.context.selectors import FromSet, Provider, Resample
from contextrl.core.env import Env, EnvState, TimeStep, tree_where


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ContextualState:
    """The inner environment state plus the episode's context, its id and the episode index."""

    env_state: EnvState
    context: Any
    context_id: jax.Array
    episode: jax.Array


@dataclasses.dataclass(frozen=True)
class ContextualEnv:
    """``env`` with a provider that picks the context of each new episode."""

    env: Env
    provider: Provider

    def __post_init__(self):
        if self.provider.space is not self.env.context_space:
            raise ContextError(
                f"the contexts belong to {self.provider.space.context_class.__name__}, "
                f"but {self.env.name} uses {self.env.context_type.__name__}"
            )

    @property
    def observation_space(self):
        return self.env.observation_space

    @property
    def action_space(self):
        return self.env.action_space

    def _choose(self, key, episode):
        """The context of episode number ``episode`` and the key left for the environment."""
        if not self.provider.uses_key:  # round robin and static: no random draw, no key split
            return (key, *self.provider(None, episode))
        select_key, env_key = jax.random.split(key)
        context, context_id = self.provider(select_key, episode)
        return env_key, context, context_id

    def reset(self, key) -> tuple[ContextualState, TimeStep]:
        episode = jnp.zeros((), jnp.int32)
        env_key, context, context_id = self._choose(key, episode)
        env_state, timestep = self.env.reset(env_key, context)
        info = {**timestep.info, "context_id": context_id, "next_context_id": context_id}
        return ContextualState(env_state, context, context_id, episode), dataclasses.replace(
            timestep, info=info
        )

    def step(self, key, state: ContextualState, action) -> tuple[ContextualState, TimeStep]:
        """One step; when the episode ends the next context is chosen and the episode restarts."""
        next_episode = state.episode + 1
        env_key, next_context, next_id = self._choose(key, next_episode)
        env_state, timestep = self.env.step_then_reset(
            env_key, state.env_state, action, state.context, next_context
        )
        done = timestep.done
        new_state = ContextualState(
            env_state,
            tree_where(done, next_context, state.context),
            jnp.where(done, next_id, state.context_id),
            jnp.where(done, next_episode, state.episode),
        )
        info = {
            **timestep.info,
            "context_id": state.context_id,
            "next_context_id": new_state.context_id,
        }
        return new_state, dataclasses.replace(timestep, info=info)


def make_provider(env: Env, contexts: Any, selector: str | Callable = "round_robin") -> Provider:
    """A provider from a batched context, a single context, a dict of features, or a distribution spec.

    A mapping whose values include a distribution is a spec to resample from at every reset; a mapping of
    plain values is one context.
    """
    space = env.context_space
    if isinstance(contexts, ContextBase):
        if not contexts.batch_shape:
            contexts = space.stack([contexts])
        return FromSet(contexts, selector)
    if isinstance(contexts, Mapping):
        if any(isinstance(v, DISTRIBUTIONS) for v in contexts.values()):
            return Resample(space, contexts)
        return FromSet(space.stack([space.make(**contexts)]), selector)
    raise ContextError(
        "contexts must be a context, a batch of contexts (crl.sample), a dict of feature values, "
        f"or a dict of distributions; got {type(contexts).__name__}"
    )


def with_contexts(
    env: Env, contexts: Any, selector: str | Callable = "round_robin"
) -> ContextualEnv:
    """``env`` whose every episode takes its context from ``contexts`` (see :func:`make_provider`)."""
    return ContextualEnv(env, make_provider(env, contexts, selector))
