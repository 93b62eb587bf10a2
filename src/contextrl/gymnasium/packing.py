"""One uint32 vector per call: how a JAX environment is stepped from Python without dispatch overhead.

Stepping one environment at a time is dominated by JAX's per-call cost, which grows with the number of
arguments and results. So the adapters declare what a program takes and returns as records (pytrees
of 32-bit and bool arrays: NamedTuples of the state, observation, reward, flags, context…), and a
:class:`Packer` turns each record into one uint32 vector, bit for bit, and back, on both sides: one
transfer each way, and no layout written by hand.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
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


def _wide(dtype: np.dtype) -> np.dtype:
    """The 32-bit dtype a leaf travels as (bools as a 0/1 word; other narrow dtypes widened)."""
    if dtype.itemsize == 4 or dtype == np.bool_:
        return dtype
    return np.dtype(np.float32 if np.issubdtype(dtype, np.floating) else np.int32)


class Packer:
    """Flattens records shaped like ``example`` (any pytree; leaves with ``shape`` and ``dtype``) to one
    uint32 vector and back: :meth:`pack` and :meth:`unpack` inside jit, :meth:`unpack_host` with NumPy.

    Fields are laid out in the record's pytree order; a None field takes no words."""

    def __init__(self, example: Any):
        leaves, self.treedef = jax.tree_util.tree_flatten(example)
        self.shapes = [tuple(leaf.shape) for leaf in leaves]
        self.dtypes = [np.dtype(leaf.dtype) for leaf in leaves]
        sizes = [math.prod(shape) for shape in self.shapes]
        self.size = sum(sizes)
        ends = itertools.accumulate(sizes)
        self.slices = [slice(end - size, end) for end, size in zip(ends, sizes, strict=True)]
        # The host's view of a vector: a NumPy record with a field per leaf, read in one ``view``
        # (a bool is read from its word's first byte: little-endian hosts).
        names = [f"f{index}" for index in range(len(leaves))]
        formats = [
            (_wide(dtype), shape) for dtype, shape in zip(self.dtypes, self.shapes, strict=True)
        ]
        offsets = [4 * part.start for part in self.slices]
        self._host_record = np.dtype(
            {"names": names, "formats": formats, "offsets": offsets, "itemsize": 4 * self.size}
        )
        self._host_fields = [
            (name, None if _wide(dtype) == dtype else dtype)
            for name, dtype in zip(names, self.dtypes, strict=True)
        ]

    @classmethod
    def of_rows(cls, example: Any) -> Packer:
        """The packer of one row of ``example``, a record batched along its leading axis (packed
        with ``jax.vmap(packer.pack)``, read back whole by :meth:`unpack_host`)."""
        return cls(
            jax.tree_util.tree_map(lambda x: jax.ShapeDtypeStruct(x.shape[1:], x.dtype), example)
        )

    def pack(self, tree: Any) -> jax.Array:
        leaves = jax.tree_util.tree_leaves(tree)
        if not leaves:
            return jnp.zeros((0,), jnp.uint32)
        return jnp.concatenate([_to_bits(jnp.asarray(leaf)) for leaf in leaves])

    def unpack(self, bits: jax.Array) -> Any:
        leaves = [
            _from_bits(bits[part], shape, dtype)
            for part, shape, dtype in zip(self.slices, self.shapes, self.dtypes, strict=True)
        ]
        return jax.tree_util.tree_unflatten(self.treedef, leaves)

    def unpack_host(self, bits: np.ndarray) -> Any:
        """:meth:`unpack` with NumPy, of one vector or of rows (leading axes kept). Fields are views of
        ``bits`` (but for narrow dtypes, converted): writing them fills a buffer for :meth:`unpack`."""
        record = bits.view(self._host_record).reshape(bits.shape[:-1])
        leaves = [
            record[name] if narrow is None else record[name].astype(narrow)
            for name, narrow in self._host_fields
        ]
        return jax.tree_util.tree_unflatten(self.treedef, leaves)

    def pack_host(self, tree: Any) -> np.ndarray:
        """:meth:`pack` with NumPy, of a record of 32-bit fields (values converted to their dtypes)."""
        leaves = jax.tree_util.tree_leaves(tree)
        words = [
            np.asarray(v, t).view(np.uint32).ravel()
            for v, t in zip(leaves, self.dtypes, strict=True)
        ]
        return np.concatenate(words) if words else np.zeros(0, np.uint32)

    def zeros_host(self) -> tuple[np.ndarray, Any]:
        """A zeroed buffer and its fields (:meth:`unpack_host`'s views), to fill on the host."""
        buffer = np.zeros(self.size, np.uint32)
        return buffer, self.unpack_host(buffer)


class PackedProgram:
    """``function(record, *args) -> record`` compiled to take and return one uint32 vector each.

    ``inputs`` and ``outputs`` are the packers of the two records, ``outputs`` read from the function's
    own result (``jax.eval_shape`` with ``args`` as examples); calling the program runs it on words.
    """

    def __init__(self, function: Callable, example: Any, *args: Any, jit: Callable = jax.jit):
        self.inputs = Packer(example)
        self.outputs = Packer(jax.eval_shape(function, example, *args))

        def on_words(words, *rest):
            return self.outputs.pack(function(self.inputs.unpack(words), *rest))

        on_words.__name__ = function.__name__  # compile logs name the program
        self._call = jit(on_words)

    def __call__(self, words: Any, *args: Any) -> np.ndarray:
        """The result's words, on the host."""
        return np.asarray(self._call(words, *args))
