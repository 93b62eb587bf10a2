"""Self-paced context evaluation (SPaCE; Eimer et al., ICML 2021): a pool of contexts grown in the
order of the agent's value estimates, wider each time performance has settled.

The agent trains on the ``size`` pool members whose start state the critic values highest, drawn
uniformly. After every update the loop reports the critic's value of each member's start state; when
the mean value over the active members changed by at most ``threshold`` (relative to its last value),
``step`` more members join. Until the first estimates the first ``initial`` members are active.
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
    mean_where,
)


class SPaCEState(NamedTuple):
    size: jax.Array  # how many members are active
    active: jax.Array  # (pool,) bool
    last_value: jax.Array  # mean start value over the active members at the last update (NaN first)


@dataclasses.dataclass(frozen=True)
class SPaCE(PoolCurriculum):
    """``SPaCE(pool, initial=4, step=4, threshold=0.05)`` over a batch of candidate contexts."""

    initial: int = 1
    step: int = 1
    threshold: float = 0.05
    name: ClassVar[str] = "space"
    needs_start_values: ClassVar[bool] = True

    def __post_init__(self):
        super().__post_init__()
        size = len(self.contexts)
        check_number("SPaCE", "initial", self.initial, 1, size, integer=True)
        check_number("SPaCE", "step", self.step, 1, size, integer=True)
        check_number("SPaCE", "threshold", self.threshold, 0.0, 1e9)

    def init(self) -> SPaCEState:
        active = jnp.arange(self.num_ids) < self.initial
        return SPaCEState(jnp.asarray(self.initial, jnp.int32), active, jnp.asarray(jnp.nan))

    def weights(self, state: SPaCEState) -> jax.Array:
        return state.active / state.active.sum()

    def update(self, state: SPaCEState, feedback: Feedback) -> SPaCEState:
        values = feedback.start_values
        value = mean_where(values, state.active)
        change = jnp.abs(value - state.last_value)
        settled = change <= self.threshold * jnp.abs(state.last_value)  # False while last is NaN
        size = jnp.where(settled, jnp.minimum(state.size + self.step, self.num_ids), state.size)
        rank = jnp.argsort(jnp.argsort(-values))  # 0: the highest value
        active = rank < size
        return SPaCEState(size.astype(jnp.int32), active, mean_where(values, active))

    def trace(self, state: SPaCEState) -> dict[str, jax.Array]:
        return {"weights": self.weights(state), "size": state.size}
