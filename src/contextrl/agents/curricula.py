"""What a training loop does for a curriculum (:mod:`contextrl.context.curricula`), PPO's and the
off-policy loop's alike: check it against the environment, build the environment its current
distribution draws from, and tell it what the last rollout showed."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from contextrl.agents.common import EpisodeLog
from contextrl.agents.networks import ContextInput
from contextrl.agents.validation import ConfigError
from contextrl.context.curricula import Curriculum, Feedback
from contextrl.core.contextual import ContextualEnv


def curriculum_of(train_contexts: Any) -> Curriculum | None:
    """``train_contexts`` when it is a curriculum, else None."""
    return train_contexts if isinstance(train_contexts, Curriculum) else None


def seen_contexts(train_contexts: Any) -> Any:
    """What the agent's context input is built from: a curriculum's contexts, or the contexts given."""
    curriculum = curriculum_of(train_contexts)
    return curriculum.train_contexts if curriculum else train_contexts


def check_curriculum(curriculum: Curriculum, env: Any, agent: str, gives_scores: bool) -> None:
    """Refuse a curriculum over another environment's contexts, or one that needs per-step scores
    (PLR's positive advantages) from a loop that does not compute them."""
    if curriculum.space is not env.context_space:
        raise ConfigError(
            f"the curriculum's contexts belong to {curriculum.space.context_class.__name__}, "
            f"but {env.name} uses {env.context_type.__name__}"
        )
    if curriculum.needs_scores and not gives_scores:
        raise ConfigError(
            f"{curriculum.name} scores contexts by the positive advantage of the rollout's steps, "
            f"which {agent}'s off-policy loop does not compute; train it with PPO, or use SPaCE or "
            "ADR"
        )


def refuse_contexts(curriculum: Curriculum | None, contexts: Any) -> None:
    """A curriculum chooses its contexts itself: ``train(key, contexts)`` cannot override them."""
    if curriculum and contexts is not None:
        raise ConfigError(
            "train(key, contexts): the agent trains under a curriculum, which chooses its "
            "contexts itself; make one train function per curriculum instead"
        )


def curriculum_env(env: Any, curriculum: Curriculum, state: Any) -> ContextualEnv:
    """The environment whose resets draw from the curriculum's distribution in ``state``."""
    return ContextualEnv(env, curriculum.provider(state))


def feedback(
    curriculum: Curriculum,
    env: Any,
    context: ContextInput,
    value: Callable[[Any, jax.Array, jax.Array], jax.Array],
    params: Any,
    log: EpisodeLog,
    key: jax.Array,
    scores: jax.Array | None = None,
) -> Feedback:
    """What the rollout the log holds (before its row closes) tells ``curriculum``: each id's mean
    return and number of ended episodes, the loop's ``scores`` where it computes them, and where the
    curriculum asks, the value ``value(params, obs, context_vector)`` of each pool member's start
    state (the same start draw from ``key`` every time)."""
    count = curriculum.num_ids
    ended = log.context_count
    if curriculum.needs_start_values:
        space, pool = env.context_space, curriculum.pool

        def start_value(ctx, member):
            _, start = env.reset(jax.random.fold_in(key, member), ctx)
            return value(params, start.obs, context.vector(space, ctx))

        start_values = jax.vmap(start_value)(pool, jnp.arange(len(pool)))
    else:
        start_values = jnp.full((count,), jnp.nan)
    return Feedback(
        returns=jnp.where(ended > 0, log.context_sum / jnp.maximum(ended, 1), jnp.nan),
        episodes=ended,
        scores=jnp.full((count,), jnp.nan) if scores is None else scores,
        start_values=start_values,
    )
