"""Evaluate a policy on a batch of contexts: every context × episode runs in one vmapped scan."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import ContextBase, ContextError
from contextrl.core.env import Env


def _check(env: Env, contexts: Any, episodes: int) -> Any:
    if not isinstance(env, Env):
        raise TypeError(f"evaluate needs a contextrl JAX environment, got {type(env).__name__}")
    if isinstance(episodes, bool) or not isinstance(episodes, (int, np.integer)) or episodes < 1:
        raise ValueError(f"episodes must be a positive integer, got {episodes!r}")
    if not isinstance(contexts, ContextBase):
        raise ContextError(
            f"contexts must be a (batched) {env.context_type.__name__}, got {type(contexts).__name__}"
        )
    env.check_context(contexts)
    return contexts if contexts.batch_shape else env.context_space.stack([contexts])


def evaluate_episodes(
    policy: Callable, params: Any, env: Env, contexts: Any, episodes: int, key
) -> jax.Array:
    """Undiscounted returns of ``episodes`` full episodes per context: shape (num_contexts, episodes).

    ``policy(params, obs, ctx, key) -> action`` acts on one observation. Each episode runs for the
    environment's time limit; rewards after its first end are ignored. Pure and jittable when the
    context batch is concrete; wrap in ``jax.jit`` for speed.
    """
    contexts = _check(env, contexts, episodes)
    num_contexts = len(contexts)

    def episode(key, ctx):
        reset_key, loop_key = jax.random.split(key)
        state, timestep = env.reset(reset_key, ctx)

        def step(carry, key):
            state, obs, total, alive = carry
            action_key, step_key = jax.random.split(key)
            action = policy(params, obs, ctx, action_key)
            state, timestep = env.step(step_key, state, action, ctx)
            total = total + jnp.where(alive, timestep.reward, 0.0)
            return (state, timestep.obs, total, alive & ~timestep.done), None

        carry = (state, timestep.obs, jnp.zeros((), jnp.float32), jnp.ones((), bool))
        (_, _, total, _), _ = jax.lax.scan(step, carry, jax.random.split(loop_key, env.max_steps))
        return total

    keys = jax.random.split(key, num_contexts * episodes).reshape(num_contexts, episodes)
    per_context = jax.vmap(lambda ks, ctx: jax.vmap(episode, in_axes=(0, None))(ks, ctx))
    return per_context(keys, contexts)


def evaluate(
    policy: Callable, params: Any, env: Env, contexts: Any, episodes: int, key
) -> jax.Array:
    """Mean undiscounted return per context: shape (num_contexts,). See :func:`evaluate_episodes`."""
    return evaluate_episodes(policy, params, env, contexts, episodes, key).mean(axis=-1)
