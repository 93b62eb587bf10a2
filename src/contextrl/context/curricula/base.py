"""What every curriculum shares: the feedback a training loop hands it, and a provider with data weights.

A curriculum is a context-sampling state that the training loop carries and updates between rollouts:
``provider(state)`` is what the next rollout's resets draw from, ``update(state, feedback)`` what the
finished rollout taught it. Both are pure and jittable and the state is data, so one compiled training
program runs under a distribution that changes every update. The curricula are agent-agnostic: they see
per-context numbers (``Feedback``), never the agent.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import jax
import jax.numpy as jnp

from contextrl.context.features import ContextBase, ContextError, ContextSpace


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Feedback:
    """What one rollout says about each context id the curriculum tracks (``num_ids`` long each).

    NaN marks "nothing to say": no episode of that id ended (``returns``), no step was taken in it
    (``scores``), or the loop was not asked for start values.
    """

    returns: jax.Array
    """Mean return of the episodes of this id that ended in the rollout."""
    episodes: jax.Array
    """How many episodes of this id ended in the rollout."""
    scores: jax.Array
    """Mean positive advantage (GAE clipped at zero) over the rollout's steps taken in this id."""
    start_values: jax.Array
    """The critic's value of each pool member's start state, after the update (SPaCE's signal)."""


@dataclasses.dataclass(frozen=True)
class WeightedSet:
    """A context set whose members are drawn with weights that are data (a traced array).

    Context id = the member's index, so a training loop's per-id bookkeeping follows the pool.
    """

    contexts: Any
    weights: jax.Array
    uses_key: ClassVar[bool] = True

    @property
    def space(self) -> ContextSpace:
        return type(self.contexts).space

    @property
    def size(self) -> int:
        return len(self.contexts)

    def __call__(self, key, episode):
        # by the inverse of the weights' cumulative sum: one uniform number a draw (a Gumbel draw
        # per member costs a reset of 64 copies from a pool of 64 a quarter of PPO's loop)
        cumulative = jnp.cumsum(self.weights)
        point = jax.random.uniform(key) * cumulative[-1]
        index = jnp.searchsorted(cumulative, point, side="right").astype(jnp.int32)
        index = jnp.minimum(index, self.size - 1)
        return self.contexts[index], index


def check_pool(contexts: Any, who: str) -> Any:
    """The candidate contexts of a pool curriculum: a concrete batch with one leading axis, ≥ 2."""
    if not isinstance(contexts, ContextBase) or len(contexts.batch_shape) != 1:
        raise ContextError(
            f"{who}: contexts must be a batch of contexts with one leading axis (crl.sample(...)), "
            f"got {type(contexts).__name__}"
        )
    type(contexts).space.check(contexts)
    if len(contexts) < 2:
        raise ContextError(f"{who}: a pool needs at least 2 contexts, got {len(contexts)}")
    return contexts


def check_number(who: str, name: str, value: Any, low: float, high: float, integer=False) -> None:
    """Refuse a parameter that is not a finite number in [low, high] (an integer where asked)."""
    kinds = (int,) if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, kinds) or not low <= value <= high:
        what = "an integer" if integer else "a number"
        raise ContextError(f"{who}: {name} must be {what} in [{low:g}, {high:g}], got {value!r}")


def mean_where(values: jax.Array, mask: jax.Array) -> jax.Array:
    """Mean of ``values`` where ``mask`` holds (NaN where it holds nowhere)."""
    count = mask.sum()
    total = jnp.where(mask, values, 0.0).sum()
    return jnp.where(count > 0, total / jnp.maximum(count, 1), jnp.nan)


class Curriculum:
    """The interface of a curriculum; a frozen dataclass implements it with pure, jittable methods.

    ``num_ids``: the context ids the loop reports on (a pool's size, ADR's boundaries).
    ``train_contexts``: what the agent's context input is built from (the contexts or the spec it may
    see). ``pool``: the contexts whose start values ``Feedback.start_values`` holds, when
    ``needs_start_values``.
    """

    name: ClassVar[str]
    needs_start_values: ClassVar[bool] = False
    needs_scores: ClassVar[bool] = False  # ``Feedback.scores``: per-step advantages (PPO's loop)

    @property
    def num_ids(self) -> int:
        raise NotImplementedError

    @property
    def train_contexts(self) -> Any:
        raise NotImplementedError

    @property
    def space(self) -> ContextSpace:
        raise NotImplementedError

    @property
    def pool(self) -> Any:
        return None

    def init(self) -> Any:
        """The state before the first rollout."""
        raise NotImplementedError

    def provider(self, state: Any) -> Any:
        """What the next rollout's resets draw contexts from (a provider of ``contextrl.context``)."""
        raise NotImplementedError

    def update(self, state: Any, feedback: Feedback) -> Any:
        """The state after a rollout that gave ``feedback``."""
        raise NotImplementedError

    def trace(self, state: Any) -> dict[str, jax.Array]:
        """The state's distribution as arrays, one row per update in the training metrics."""
        raise NotImplementedError


@dataclasses.dataclass(frozen=True)
class PoolCurriculum(Curriculum):
    """A curriculum over a fixed pool of candidate contexts, drawn by weights; id = member index."""

    contexts: Any

    def __post_init__(self):
        check_pool(self.contexts, type(self).__name__)

    @property
    def num_ids(self) -> int:
        return len(self.contexts)

    @property
    def space(self) -> ContextSpace:
        return type(self.contexts).space

    @property
    def train_contexts(self) -> Any:
        return self.contexts

    @property
    def pool(self) -> Any:
        return self.contexts

    def weights(self, state: Any) -> jax.Array:
        raise NotImplementedError

    def provider(self, state: Any) -> WeightedSet:
        return WeightedSet(self.contexts, self.weights(state))
