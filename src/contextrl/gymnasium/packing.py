"""One uint32 vector per call: how a JAX environment is stepped from Python without dispatch overhead.

Stepping one environment at a time is dominated by JAX's per-call cost, which grows with the number of
arguments and results. So the adapters flatten the whole state (a pytree of 32-bit and bool arrays) into
one uint32 vector, bit for bit, pass it in with the action and get one vector back: one transfer each way.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax


def _to_bits(leaf: jax.Array) -> jax.Array:
    if leaf.dtype == jnp.bool_:
        return leaf.astype(jnp.uint32).ravel()
    if leaf.dtype.itemsize != 4:
        wide = jnp.float32 if jnp.issubdtype(leaf.dtype, jnp.floating) else jnp.int32
        leaf = leaf.astype(wide)
    return lax.bitcast_convert_type(leaf, jnp.uint32).ravel()


def _from_bits(bits: jax.Array, shape: tuple[int, ...], dtype: Any) -> jax.Array:
    dtype = jnp.dtype(dtype)
    if dtype == jnp.bool_:
        return (bits != 0).reshape(shape)
    if dtype.itemsize != 4:
        wide = jnp.float32 if jnp.issubdtype(dtype, jnp.floating) else jnp.int32
        return lax.bitcast_convert_type(bits, wide).astype(dtype).reshape(shape)
    return lax.bitcast_convert_type(bits, dtype).reshape(shape)


class Packer:
    """Flattens pytrees shaped like ``example`` to one uint32 vector and back (inside jit)."""

    def __init__(self, example: Any):
        leaves, self.treedef = jax.tree_util.tree_flatten(example)
        self.shapes = [tuple(leaf.shape) for leaf in leaves]
        self.dtypes = [jnp.dtype(leaf.dtype) for leaf in leaves]
        self.sizes = [math.prod(shape) for shape in self.shapes]
        self.size = sum(self.sizes)

    def pack(self, tree: Any) -> jax.Array:
        leaves = jax.tree_util.tree_leaves(tree)
        if not leaves:
            return jnp.zeros((0,), jnp.uint32)
        return jnp.concatenate([_to_bits(jnp.asarray(leaf)) for leaf in leaves])

    def unpack(self, bits: jax.Array) -> Any:
        leaves, start = [], 0
        for shape, dtype, size in zip(self.shapes, self.dtypes, self.sizes, strict=True):
            leaves.append(_from_bits(bits[start : start + size], shape, dtype))
            start += size
        return jax.tree_util.tree_unflatten(self.treedef, leaves)

    def unpack_host(self, bits: np.ndarray) -> Any:
        """The same as :meth:`unpack`, on the host with NumPy (for rendering)."""
        leaves, start = [], 0
        for shape, dtype, size in zip(self.shapes, self.dtypes, self.sizes, strict=True):
            chunk = np.asarray(bits[start : start + size], np.uint32)
            if dtype == np.bool_:
                value = chunk != 0
            elif dtype.itemsize != 4:
                wide = np.float32 if np.issubdtype(dtype, np.floating) else np.int32
                value = chunk.view(wide).astype(dtype)
            else:
                value = chunk.view(dtype)
            leaves.append(value.reshape(shape))
            start += size
        return jax.tree_util.tree_unflatten(self.treedef, leaves)
