"""Prioritised level replay over contexts (PLR; Jiang et al., 2021, "Prioritized Level Replay"): a pool
of contexts scored by the agent's positive value loss, replayed by rank with a pull towards the stale.

Each member has a score (the mean positive advantage of its last rollout steps: where the critic
underestimated the return, there is something left to learn), the update at which it was last played
and whether it was ever played. A rollout's resets draw with weights

    P_replay = (1 − staleness) · P_score + staleness · P_stale     over the members played before,
    P_score ∝ (1 / rank of the score) ** (1 / temperature),  P_stale ∝ updates since last played,

mixed as ``replay_probability · P_replay + (1 − replay_probability) · uniform over the unplayed``
(all replay once every member was played; all new before any was). Robust PLR's other half, training
only on replayed contexts, is not done here: every rollout trains the agent.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp

from contextrl.context.curricula.base import (
    Feedback,
    PoolCurriculum,
    check_number,
)


class PLRState(NamedTuple):
    scores: jax.Array  # (pool,) latest score of each member
    last_played: jax.Array  # (pool,) update index of its last rollout
    played: jax.Array  # (pool,) bool
    updates: jax.Array  # updates so far


@dataclasses.dataclass(frozen=True)
class PLR(PoolCurriculum):
    """``PLR(pool, replay_probability=0.5, temperature=0.1, staleness=0.1)``."""

    replay_probability: float = 0.5
    temperature: float = 0.1
    staleness: float = 0.1
    name: ClassVar[str] = "plr"
    needs_scores: ClassVar[bool] = True

    def __post_init__(self):
        super().__post_init__()
        check_number("PLR", "replay_probability", self.replay_probability, 0.0, 1.0)
        check_number("PLR", "temperature", self.temperature, 1e-6, 1e6)
        check_number("PLR", "staleness", self.staleness, 0.0, 1.0)

    def init(self) -> PLRState:
        size = self.num_ids
        return PLRState(
            jnp.zeros((size,), jnp.float32),
            jnp.zeros((size,), jnp.int32),
            jnp.zeros((size,), bool),
            jnp.zeros((), jnp.int32),
        )

    def replay_weights(self, state: PLRState) -> jax.Array:
        """P_replay over the played members (zero elsewhere)."""
        played = state.played
        order = jnp.argsort(jnp.argsort(-jnp.where(played, state.scores, -jnp.inf)))
        by_rank = jnp.where(played, (1.0 / (order + 1.0)) ** (1.0 / self.temperature), 0.0)
        by_rank = by_rank / jnp.maximum(by_rank.sum(), 1e-30)
        age = jnp.where(played, (state.updates - state.last_played).astype(jnp.float32), 0.0)
        stale = jnp.where(
            age.sum() > 0,
            age / jnp.maximum(age.sum(), 1e-30),
            played / jnp.maximum(played.sum(), 1),
        )
        return (1.0 - self.staleness) * by_rank + self.staleness * stale

    def weights(self, state: PLRState) -> jax.Array:
        played = state.played
        unplayed = ~played
        new = unplayed / jnp.maximum(unplayed.sum(), 1)
        replay = self.replay_weights(state)
        mixed = self.replay_probability * replay + (1.0 - self.replay_probability) * new
        return jnp.where(~played.any(), new, jnp.where(played.all(), replay, mixed))

    def update(self, state: PLRState, feedback: Feedback) -> PLRState:
        now = jnp.isfinite(feedback.scores)
        return PLRState(
            jnp.where(now, feedback.scores, state.scores),
            jnp.where(now, state.updates, state.last_played).astype(jnp.int32),
            state.played | now,
            state.updates + 1,
        )

    def trace(self, state: PLRState) -> dict[str, jax.Array]:
        return {"weights": self.weights(state)}
