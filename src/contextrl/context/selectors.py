"""Where the next episode's context comes from: a context set with a selector, or a distribution.

Both are pure and jittable: a *provider* turns ``(key, episode_index)`` into ``(context, context_id)``,
so the choice happens at reset inside a compiled loop, with no host round trip. The episode index is the
only selector state, so a provider needs nothing besides what the environment state already carries.
It is the *global* episode index: copy ``i`` of ``N`` runs episodes ``i, i + N, i + 2N, …``, so round
robin over N contexts with N copies gives copy ``i`` context ``i``, and a custom selector knows which
copy it serves (``episode % N``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import jax
import jax.numpy as jnp

from contextrl.context.distributions import Distribution, check_spec, draw
from contextrl.context.features import ContextError, ContextSpace

SELECTORS = ("round_robin", "random", "static")
DEFAULT_SELECTOR = "round_robin"  # the one default of every face: envs, gymnasium, agents


@dataclasses.dataclass(frozen=True)
class RoundRobin:
    """Contexts in order, one per episode, wrapping around."""

    uses_key = False

    def __call__(self, key, episode, n):
        return episode % n


@dataclasses.dataclass(frozen=True)
class RandomSelector:
    """A uniformly random context per episode, drawn from the reset key (never a global RNG)."""

    uses_key = True

    def __call__(self, key, episode, n):
        return jax.random.randint(key, (), 0, n)


@dataclasses.dataclass(frozen=True)
class Static:
    """Always the same context (index into the set)."""

    index: int = 0
    uses_key = False

    def __call__(self, key, episode, n):
        return jnp.asarray(self.index, jnp.int32)


@dataclasses.dataclass(frozen=True)
class Custom:
    """A user function ``fn(key, episode_index, num_contexts) -> index``, traced into the loop."""

    fn: Callable[[Any, Any, int], Any]
    uses_key = True

    def __call__(self, key, episode, n):
        return jnp.asarray(self.fn(key, episode, n), jnp.int32)


def make_selector(selector: str | Callable | Any) -> Callable:
    """A selector object from a name ("round_robin", "random", "static") or a callable."""
    if isinstance(selector, (RoundRobin, RandomSelector, Static, Custom)):
        return selector
    if isinstance(selector, str):
        named = {"round_robin": RoundRobin(), "random": RandomSelector(), "static": Static()}
        if selector not in named:
            raise ContextError(
                f"unknown context selector {selector!r}; choose one of {list(SELECTORS)}"
            )
        return named[selector]
    if callable(selector):
        return Custom(selector)
    raise ContextError(
        f"context selector must be one of {list(SELECTORS)} or a callable, got {selector!r}"
    )


@dataclasses.dataclass(frozen=True)
class FromSet:
    """A fixed set of contexts (a batched context) and a selector that picks one per episode."""

    contexts: Any
    selector: Callable = RoundRobin()

    def __post_init__(self):
        type(self.contexts).space.check(self.contexts)
        if len(self.contexts.batch_shape) != 1:
            raise ContextError(
                f"a context set must be a batch with one leading axis, got {self.contexts.batch_shape}"
            )
        object.__setattr__(self, "selector", make_selector(self.selector))
        if isinstance(self.selector, Static) and not 0 <= self.selector.index < self.size:
            raise ContextError(
                f"static selector index {self.selector.index} is outside the set of {self.size}"
            )

    @property
    def size(self) -> int:
        return len(self.contexts)

    @property
    def uses_key(self) -> bool:
        return self.selector.uses_key

    @property
    def space(self) -> ContextSpace:
        return type(self.contexts).space

    def __call__(self, key, episode):
        index = jnp.asarray(self.selector(key, episode, self.size), jnp.int32)
        return self.contexts[index], index


@dataclasses.dataclass(frozen=True)
class Resample:
    """A fresh context drawn from a distribution spec at every reset (context id -1)."""

    space: ContextSpace
    spec: Mapping[str, Distribution]
    uses_key = True

    def __post_init__(self):
        if any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(self.spec)):
            # Parameters a compiled loop carries (a curriculum's): checked where they were concrete.
            spec = {self.space.resolve(name): d for name, d in self.spec.items()}
        else:
            spec = check_spec(self.space, self.spec)
        object.__setattr__(self, "spec", spec)
        if not self.spec:
            raise ContextError("a resampling spec needs at least one feature distribution")

    def __call__(self, key, episode):
        return draw(self.space, self.spec, 1, key)[0], jnp.asarray(-1, jnp.int32)


Provider = FromSet | Resample
