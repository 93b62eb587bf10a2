"""Network pieces shared by every agent: MLPs in plain JAX and the context encoders.

Parameters are nested dicts of arrays (a pytree), so they vmap over seeds, save to a checkpoint and
load back without a framework. How the agent sees the context (its ``variant``; the features it reads
are normalised as environments normalise a visible context: :class:`contextrl.context.ContextObservation`)
is one of four :data:`VARIANTS`:

- ``hidden``: the network gets the observation only (the context-oblivious baseline);
- ``concat_all``: every context feature, normalised by its bounds to [0, 1], is appended to the input;
- ``concat_varying``: only the features that vary in the training contexts are appended;
- ``gated``: the first hidden layer of the observation is multiplied, element-wise, by a context
  encoder's output in (0, 2) (the "cGate" idea: the context modulates state features instead of
  being one more input among many).

The context vector is always built by the agent from the environment state's context, never read from
the observation, so "concat_varying" can be computed from the training set.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.agents.validation import ConfigError
from contextrl.context.features import ContextBase, ContextSpace
from contextrl.context.observation import ContextObservation
from contextrl.context.schedule import resolve_contexts

VARIANTS = ("hidden", "concat_all", "concat_varying", "gated")  # how an agent sees the context
ACTIVATIONS = {"tanh": jnp.tanh, "relu": jax.nn.relu}

Params = dict[str, Any]


def orthogonal(key, n_in: int, n_out: int, scale: float) -> jax.Array:
    """A random (semi-)orthogonal matrix times ``scale``, by Gram–Schmidt on a Gaussian matrix.

    Written with matmuls instead of ``jax.nn.initializers.orthogonal``: its LAPACK QR kernel, batched
    under ``vmap`` inside a compiled loop, can deadlock XLA's CPU thread pool on a 2-core machine.
    """
    long, short = max(n_in, n_out), min(n_in, n_out)
    gaussian = jax.random.normal(key, (long, short), jnp.float32)
    columns = jnp.arange(short)

    def orthonormalise(i, q):
        vector = q[:, i]
        for _ in range(2):  # twice: "twice is enough" for numerical orthogonality
            vector = vector - q @ jnp.where(columns < i, q.T @ vector, 0.0)
        return q.at[:, i].set(vector / jnp.linalg.norm(vector))

    q = jax.lax.fori_loop(0, short, orthonormalise, gaussian)
    return scale * (q if n_in >= n_out else q.T)


def dense_init(key, n_in: int, n_out: int, scale: float) -> Params:
    """Orthogonal weights scaled by ``scale`` and zero biases (the PPO/CleanRL initialisation)."""
    return {"kernel": orthogonal(key, n_in, n_out, scale), "bias": jnp.zeros((n_out,), jnp.float32)}


def dense(params: Params, x: jax.Array) -> jax.Array:
    return x @ params["kernel"] + params["bias"]


@dataclasses.dataclass(frozen=True)
class ContextInput:
    """How a network is conditioned (``variant``) on which features (``view``, normalised to [0, 1])."""

    variant: str = "hidden"
    view: ContextObservation = ContextObservation()

    @property
    def size(self) -> int:
        return len(self.view.features)

    def vector(self, space: ContextSpace, context: Any) -> jax.Array:
        """The normalised context features (in [0, 1]) the network sees; empty when hidden."""
        if self.view.hidden:
            return jnp.zeros(jnp.shape(getattr(context, space.names[0])) + (0,), jnp.float32)
        return self.view.values(space, context)


def varying_features(space: ContextSpace, train_contexts: Any) -> tuple[str, ...]:
    """Features that vary in a context set, or that a distribution spec draws non-constantly."""
    if isinstance(train_contexts, ContextBase) and not train_contexts.batch_shape:
        return ()
    schedule = resolve_contexts(space, train_contexts)
    return schedule.observation("varying", normalize=True, noise=0.0).features


def check_variant(variant: Any) -> None:
    """Refuse a variant that is not one of :data:`VARIANTS`, listing them."""
    if variant not in VARIANTS:
        raise ConfigError(f"variant: unknown {variant!r}; choose one of {list(VARIANTS)}")


def context_input(variant: str, space: ContextSpace, train_contexts: Any) -> ContextInput:
    """Resolve a variant against the environment's context space and the training contexts."""
    check_variant(variant)
    if variant == "hidden":
        return ContextInput()
    if variant == "concat_varying":
        names = varying_features(space, train_contexts)
        if not names:
            raise ConfigError(
                "variant='concat_varying': no context feature varies in the training contexts, "
                "so there is nothing to append; use 'hidden' or 'concat_all'"
            )
    else:
        names = space.names
    return ContextInput(variant, ContextObservation(features=tuple(names), normalize=True))


@dataclasses.dataclass(frozen=True)
class ConditionedMLP:
    """An MLP from (input, context vector) to ``out_size`` outputs, conditioned as ``context`` says."""

    in_size: int
    out_size: int
    hidden_sizes: tuple[int, ...]
    context: ContextInput = ContextInput()
    activation: str = "tanh"
    out_scale: float = 1.0
    layer_norm: bool = False
    """The first hidden layer normalised (LayerNorm, learned scale and offset), then tanh, whatever
    ``activation`` the others use: the SAC networks of CARL's experiments."""

    def init(self, key) -> Params:
        sizes = list(self.hidden_sizes)
        first_in = self.in_size + (
            self.context.size if self.context.variant.startswith("concat") else 0
        )
        keys = jax.random.split(key, len(sizes) + 2)
        params: Params = {}
        n_in = first_in
        for i, width in enumerate(sizes):
            params[f"layer_{i}"] = dense_init(keys[i], n_in, width, math.sqrt(2.0))
            n_in = width
        params["out"] = dense_init(keys[len(sizes)], n_in, self.out_size, self.out_scale)
        if self.layer_norm:
            params["norm"] = {"scale": jnp.ones((sizes[0],)), "offset": jnp.zeros((sizes[0],))}
        if self.context.variant == "gated":
            # Zero weights and bias: the gate starts at exactly 1, i.e. as the hidden agent.
            params["gate"] = dense_init(keys[-1], self.context.size, sizes[0], 0.0)
        return params

    def apply(self, params: Params, x: jax.Array, context_vector: jax.Array) -> jax.Array:
        activation = ACTIVATIONS[self.activation]
        if self.context.variant.startswith("concat"):
            x = jnp.concatenate([x, context_vector], axis=-1)
        for i in range(len(self.hidden_sizes)):
            x = dense(params[f"layer_{i}"], x)
            x = (
                jnp.tanh(layer_norm(params["norm"], x))
                if i == 0 and self.layer_norm
                else activation(x)
            )
            if i == 0 and self.context.variant == "gated":
                x = x * 2.0 * jax.nn.sigmoid(dense(params["gate"], context_vector))
        return dense(params["out"], x)


def layer_norm(params: Params, x: jax.Array, eps: float = 1e-5) -> jax.Array:
    """``x`` normalised over its last axis to zero mean and unit variance, then scaled and shifted."""
    mean = x.mean(axis=-1, keepdims=True)
    variance = jnp.square(x - mean).mean(axis=-1, keepdims=True)
    return (x - mean) * jax.lax.rsqrt(variance + eps) * params["scale"] + params["offset"]


def check_hidden_sizes(value: Sequence[int], activation: str) -> tuple[int, ...]:
    if not isinstance(value, (list, tuple)) or not all(
        isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v > 0 for v in value
    ):
        raise ConfigError(
            f"hidden_sizes must be a non-empty list of positive integers (a width per layer, e.g. "
            f"[64, 64]), got {value!r}"
        )
    if len(value) == 0:
        raise ConfigError("hidden_sizes must list at least one layer width")
    if activation not in ACTIVATIONS:
        raise ConfigError(f"activation: unknown {activation!r}; choose one of {list(ACTIVATIONS)}")
    return tuple(int(v) for v in value)
