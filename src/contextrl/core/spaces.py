"""Action and observation spaces that sample from a JAX key and convert to gymnasium."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np


@dataclasses.dataclass(frozen=True)
class Discrete:
    """Integers 0 … n−1."""

    n: int

    shape = ()
    dtype = jnp.int32

    def sample(self, key) -> jax.Array:
        return jax.random.randint(key, (), 0, self.n)

    def contains(self, x) -> bool:
        x = np.asarray(x)
        return x.shape == () and x.dtype.kind in "iu" and 0 <= int(x) < self.n

    def to_gymnasium(self):
        import gymnasium

        return gymnasium.spaces.Discrete(self.n)


@dataclasses.dataclass(frozen=True, eq=False)
class Box:
    """A float32 box [low, high] (bounds may be infinite)."""

    low: np.ndarray
    high: np.ndarray

    def __post_init__(self):
        low = np.asarray(self.low, np.float32)
        high = np.broadcast_to(np.asarray(self.high, np.float32), low.shape).copy()
        if np.any(low > high):
            raise ValueError("Box low must not exceed high")
        object.__setattr__(self, "low", low)
        object.__setattr__(self, "high", high)

    @property
    def shape(self) -> tuple[int, ...]:
        return self.low.shape

    dtype = jnp.float32

    def sample(self, key) -> jax.Array:
        """Uniform where bounded, a standard normal shifted into half-open bounds otherwise."""
        uniform_key, normal_key = jax.random.split(key)
        u = jax.random.uniform(uniform_key, self.shape)
        z = jax.random.normal(normal_key, self.shape)
        low, high = self.low, self.high
        bounded = np.isfinite(low) & np.isfinite(high)
        finite_low = np.where(np.isfinite(low), low, 0.0)
        finite_high = np.where(np.isfinite(high), high, 0.0)
        value = jnp.where(
            bounded,
            finite_low + u * (finite_high - finite_low),
            jnp.where(
                np.isfinite(low),
                finite_low + jnp.abs(z),
                jnp.where(np.isfinite(high), finite_high - jnp.abs(z), z),
            ),
        )
        return value.astype(jnp.float32)

    def contains(self, x) -> bool:
        x = np.asarray(x)
        return (
            x.shape == self.shape
            and bool(np.all(np.isfinite(x) | np.isinf(self.low) | np.isinf(self.high)))
            and bool(np.all((x >= self.low) & (x <= self.high)))
        )

    def to_gymnasium(self):
        import gymnasium

        return gymnasium.spaces.Box(self.low, self.high, dtype=np.float32)
