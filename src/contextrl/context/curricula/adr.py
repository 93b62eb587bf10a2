"""Automatic domain randomisation (ADR; OpenAI et al., 2019, "Solving Rubik's Cube with a Robot Hand"):
per feature, a range that widens where the agent does well at its edge and narrows where it fails.

Each episode draws every adapted feature uniformly from its current range, except that with
``boundary_probability`` one feature (chosen uniformly, and one of its two edges) is pinned to that
edge: those episodes carry the edge's id (``2 × feature + 0`` for low, ``+ 1`` for high) and their
returns fill the edge's buffer. Once an edge has ``buffer_size`` returns, their mean decides: at or
above ``widen_above`` the edge moves out by ``delta`` × the outer width, at or below
``narrow_below`` it moves in as far; the buffer empties either way. An edge never passes the feature's outer bounds (``ranges``, within the
declared bounds) and never crosses the other edge.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.curricula.base import Curriculum, Feedback, check_number
from contextrl.context.distributions import Uniform
from contextrl.context.features import ContextError, ContextSpace


class ADRState(NamedTuple):
    low: jax.Array  # (features,) current ranges
    high: jax.Array
    buffer_sum: jax.Array  # (2 × features,) returns collected at each edge since its last decision
    buffer_count: jax.Array


@dataclasses.dataclass(frozen=True)
class EdgeSampler:
    """Every adapted feature uniform in [low, high]; with a probability one edge is pinned (its id)."""

    space: ContextSpace
    names: tuple[str, ...]
    low: jax.Array
    high: jax.Array
    boundary_probability: float
    uses_key: ClassVar[bool] = True

    def __call__(self, key, episode):
        draw_key, pin_key, edge_key = jax.random.split(key, 3)
        count = len(self.names)
        values = jax.random.uniform(draw_key, (count,), minval=self.low, maxval=self.high)
        pinned = jax.random.uniform(pin_key) < self.boundary_probability
        edge = jax.random.randint(edge_key, (), 0, 2 * count)
        feature, upper = edge // 2, edge % 2
        edge_value = jnp.where(upper == 1, self.high[feature], self.low[feature])
        values = jnp.where(pinned & (jnp.arange(count) == feature), edge_value, values)
        default = self.space.default()
        fields = {**default.as_dict()}
        for index, name in enumerate(self.names):
            fields[name] = values[index].astype(self.space.features[name].dtype)
        context = self.space.context_class(**fields)
        return context, jnp.where(pinned, edge, -1).astype(jnp.int32)


@dataclasses.dataclass(frozen=True)
class ADR(Curriculum):
    """``ADR(env.context_space, {"pole_length": (0.1, 5.0)}, widen_above=400, narrow_below=100)``."""

    context_space: ContextSpace
    ranges: Mapping[str, tuple[float, float]]
    widen_above: float
    narrow_below: float
    start: Mapping[str, tuple[float, float]] | None = None
    delta: float = 0.05
    buffer_size: int = 8
    boundary_probability: float = 0.5
    name: ClassVar[str] = "adr"

    def __post_init__(self):
        if not isinstance(self.ranges, Mapping) or not self.ranges:
            raise ContextError("ADR: ranges must map at least one feature to its outer (low, high)")
        space = self.context_space
        ranges = {space.resolve(name): _pair(name, r, "ranges") for name, r in self.ranges.items()}
        for name in ranges:
            if space.features[name].kind != "float":
                raise ContextError(
                    f"ADR: {name} is {space.features[name].kind}; ADR widens ranges of float "
                    "features only"
                )
        for name, (low, high) in ranges.items():
            Uniform(low, high).check(space.features[name])
        space.check_ranges(ranges, "ADR's outer ranges")
        start = {name: (space.features[name].default,) * 2 for name in ranges}
        for name, pair in (self.start or {}).items():
            canonical = space.resolve(name)
            if canonical not in ranges:
                raise ContextError(f"ADR: start gives {canonical}, which ranges does not adapt")
            start[canonical] = _pair(name, pair, "start")
        for name, (low, high) in start.items():
            outer = ranges[name]
            if not outer[0] <= low <= high <= outer[1]:
                raise ContextError(
                    f"ADR: {name} starts at [{low:g}, {high:g}] (the default unless start gives "
                    f"it), not inside its outer range [{outer[0]:g}, {outer[1]:g}]"
                )
        object.__setattr__(self, "ranges", ranges)
        object.__setattr__(self, "start", start)
        for name in ("widen_above", "narrow_below"):
            check_number("ADR", name, getattr(self, name), -1e12, 1e12)
        if self.narrow_below >= self.widen_above:
            raise ContextError(
                f"ADR: narrow_below ({self.narrow_below:g}) must be below widen_above "
                f"({self.widen_above:g})"
            )
        check_number("ADR", "delta", self.delta, 1e-9, 1.0)
        check_number("ADR", "buffer_size", self.buffer_size, 1, 10**6, integer=True)
        check_number("ADR", "boundary_probability", self.boundary_probability, 0.0, 1.0)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.ranges)

    @property
    def space(self) -> ContextSpace:
        return self.context_space

    @property
    def num_ids(self) -> int:
        return 2 * len(self.ranges)

    @property
    def train_contexts(self) -> dict[str, Uniform]:
        """The outer ranges: every value ADR can reach (what a context input normalises over)."""
        return {name: Uniform(*pair) for name, pair in self.ranges.items()}

    def _outer(self) -> tuple[np.ndarray, np.ndarray]:
        return tuple(np.asarray([r[i] for r in self.ranges.values()], np.float32) for i in (0, 1))

    def init(self) -> ADRState:
        low = jnp.asarray([self.start[name][0] for name in self.names], jnp.float32)
        high = jnp.asarray([self.start[name][1] for name in self.names], jnp.float32)
        zeros = jnp.zeros((self.num_ids,), jnp.float32)
        return ADRState(low, high, zeros, zeros.astype(jnp.int32))

    def provider(self, state: ADRState) -> EdgeSampler:
        return EdgeSampler(self.space, self.names, state.low, state.high, self.boundary_probability)

    def update(self, state: ADRState, feedback: Feedback) -> ADRState:
        ended = feedback.episodes.astype(jnp.int32)
        total = state.buffer_sum + jnp.where(ended > 0, feedback.returns * ended, 0.0)
        count = state.buffer_count + ended
        full = count >= self.buffer_size
        mean = total / jnp.maximum(count, 1)
        move = jnp.where(full & (mean >= self.widen_above), 1.0, 0.0)
        move = jnp.where(full & (mean <= self.narrow_below), -1.0, move)
        outer_low, outer_high = self._outer()
        width = jnp.asarray(outer_high - outer_low) * self.delta  # a step: delta × the outer width
        low = state.low - move[0::2] * width
        high = state.high + move[1::2] * width
        low = jnp.clip(low, outer_low, state.high)
        high = jnp.clip(high, low, outer_high)
        return ADRState(
            low,
            high,
            jnp.where(full, 0.0, total),
            jnp.where(full, 0, count).astype(jnp.int32),
        )

    def trace(self, state: ADRState) -> dict[str, jax.Array]:
        return {"low": state.low, "high": state.high}


def _pair(name: str, value: Any, what: str) -> tuple[float, float]:
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ContextError(f"ADR: {what}[{name!r}] must be (low, high), got {value!r}") from None
    if not (np.isfinite(low) and np.isfinite(high)) or low > high:
        raise ContextError(f"ADR: {what}[{name!r}] must be finite with low <= high, got {value!r}")
    return low, high
