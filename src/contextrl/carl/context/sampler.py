"""CARL's ``ContextSampler``: a context set drawn from feature distributions, seeded.

The distributions are checked against the environment's bounds when the sampler is built; every call to
``sample_contexts`` draws fresh contexts from the seed and the call's number, so a script reproduces.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import jax

from contextrl.carl.context.context_space import ContextFeature, ContextSpace
from contextrl.carl.utils.types import Context, Contexts
from contextrl.context.distributions import draw
from contextrl.context.features import ContextError


class ContextSampler:
    """Contexts whose listed features follow their distributions; the others keep their defaults."""

    def __init__(
        self,
        context_distributions: Sequence[ContextFeature] | Mapping[str, ContextFeature],
        context_space: ContextSpace,
        seed: int,
        name: str | None = None,
    ):
        if isinstance(context_distributions, Mapping):
            context_distributions = list(context_distributions.values())
        if not isinstance(context_distributions, Sequence) or not all(
            isinstance(f, ContextFeature) for f in context_distributions
        ):
            raise ContextError(
                "context_distributions must be a list or dict of context features "
                f"(UniformFloatContextFeature, NormalFloatContextFeature, ...), got "
                f"{context_distributions!r}"
            )
        self.context_distributions = list(context_distributions)
        self.context_space = context_space
        self.name = name
        self.spec = context_space.spec_of(self.context_distributions)
        self.context_feature_names = list(self.spec)
        self.seed(seed)

    def seed(self, seed: int) -> None:
        """Draw from ``seed`` from now on, as if the sampler were new (CARL's sampler, a ConfigSpace
        space, has this method; Mighty reseeds it between its training and evaluation sets)."""
        if isinstance(seed, bool) or not isinstance(seed, int):
            raise ContextError(f"seed must be an integer, got {seed!r}")
        self._seed = seed
        self._calls = 0

    def get_context_features(self) -> list[ContextFeature]:
        return list(self.context_distributions)

    def sample_contexts(self, n_contexts: int) -> Contexts:
        """``n_contexts`` contexts as a mapping 0 … n−1 → context (a dict of every feature's value)."""
        return dict(enumerate(self._sample_contexts(n_contexts)))

    def _sample_contexts(self, size: int = 1) -> list[Context]:
        if isinstance(size, bool) or not isinstance(size, int) or size < 1:
            raise ContextError(f"the number of contexts must be a positive integer, got {size!r}")
        key = jax.random.fold_in(jax.random.key(self._seed), self._calls)
        self._calls += 1
        core = self.context_space.core
        batch = draw(core, self.spec, size, key)
        return [self.context_space.plain(batch[i]) for i in range(size)]
