"""CARL's context selectors, choosing with contextrl's own selectors.

Inside an environment the random and static selectors are handed to contextrl's core, which picks each
episode's context from the reset seed; the selector object is kept up to date (``context_id``,
``n_calls``) so code that reads it still works. Round robin, a ``CustomSelector`` and a user's subclass
are asked for the context at every reset, so the cycle goes on across seeded resets as in CARL (a seed
starts the core's own schedule over). Called on their own, ``select()`` uses the same core selectors.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax

from contextrl.carl.utils.types import Context, Contexts
from contextrl.context import selectors as core


class AbstractSelector:
    """The base of every selector: the context set, its keys, the current position and the call count.

    ``context_id`` is the position of the current context in ``contexts`` (None before the first call),
    ``context_key`` its key.
    """

    def __init__(self, contexts: Contexts):
        self.contexts: Contexts = contexts
        self.context_ids: list[int] = list(range(len(contexts)))
        self.contexts_keys: list[Any] = list(contexts)
        self.n_calls: int = 0
        self.context_id: int | None = None

    def _select(self) -> tuple[Context, int]:
        raise NotImplementedError("a selector implements _select() -> (context, position)")

    def select(self) -> Context:
        context, context_id = self._select()
        self.context_id = int(context_id)
        self.n_calls += 1
        return context

    @property
    def context_key(self) -> Any | None:
        return None if self.context_id is None else self.contexts_keys[self.context_id]

    def record(self, key: Any) -> None:
        """An environment chose the context ``key`` for a new episode."""
        self.context_id = self.contexts_keys.index(key)
        self.n_calls += 1

    def _chosen(self, index) -> tuple[Context, int]:
        index = int(index)
        return self.contexts[self.contexts_keys[index]], index


class RoundRobinSelector(AbstractSelector):
    """The contexts in order, one per episode, then from the first again."""

    def core_selector(self) -> core.RoundRobin:
        return core.RoundRobin()

    def _select(self) -> tuple[Context, int]:
        return self._chosen(self.core_selector()(None, self.n_calls, len(self.contexts)))


class RandomSelector(AbstractSelector):
    """A uniformly random context per episode. In an environment the choice comes from the reset seed;
    on its own, from ``seed``."""

    def __init__(self, contexts: Contexts, seed: int = 0):
        super().__init__(contexts)
        self.seed = seed

    def core_selector(self) -> core.RandomSelector:
        return core.RandomSelector()

    def _select(self) -> tuple[Context, int]:
        key = jax.random.fold_in(jax.random.key(self.seed), self.n_calls)
        return self._chosen(self.core_selector()(key, self.n_calls, len(self.contexts)))


class StaticSelector(AbstractSelector):
    """Always the same context: the first, or the one ``context_id`` was set to."""

    def core_selector(self) -> core.Static:
        return core.Static(self.context_id or 0)

    def _select(self) -> tuple[Context, int]:
        return self._chosen(self.core_selector()(None, self.n_calls, len(self.contexts)))


BUILT_IN = (RandomSelector, StaticSelector)  # chosen by the core in an environment


class CustomSelector(AbstractSelector):
    """Selection by ``selector_function(selector) -> (context, position)``, called at every reset."""

    def __init__(
        self,
        contexts: Contexts,
        selector_function: Callable[[AbstractSelector], tuple[Context, int]],
    ):
        super().__init__(contexts)
        if not callable(selector_function):
            raise TypeError(f"selector_function must be callable, got {selector_function!r}")
        self.selector_function = selector_function

    def _select(self) -> tuple[Context, int]:
        return self.selector_function(self)
