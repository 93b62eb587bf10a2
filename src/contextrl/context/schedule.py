"""The one parser of ``contexts=``: every face (core, gymnasium, agents, CARL/gymnax faces) calls it.

Users hand contexts over in many shapes (one dict of values, a context object, a mapping id → context,
a list, a batch from ``crl.sample``, a distribution spec). They all become one :class:`ContextSchedule`:
a pure JAX provider that picks the context of each episode, plus the ids users see in ``info``.
The default selector is :data:`DEFAULT_SELECTOR` ("round_robin") everywhere.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Hashable, Mapping, Sequence
from typing import Any

import numpy as np

from contextrl.context.distributions import DISTRIBUTIONS, Constant
from contextrl.context.features import ContextBase, ContextError, ContextSpace
from contextrl.context.observation import ContextObservation
from contextrl.context.selectors import DEFAULT_SELECTOR, FromSet, Resample, make_selector

RESAMPLED_ID = -1  # the id of a context that is not from the set (resampled, or given to reset)


@dataclasses.dataclass(frozen=True)
class ContextSchedule:
    """Where each episode's context comes from, and the ids users see for the set's members."""

    space: ContextSpace
    provider: FromSet | Resample
    ids: tuple[Any, ...]  # user-facing id of each member of the set (empty when resampling)

    @property
    def resamples(self) -> bool:
        return isinstance(self.provider, Resample)

    def user_id(self, index: int) -> Any:
        """The id users see for a set index (``RESAMPLED_ID`` for contexts from elsewhere)."""
        return RESAMPLED_ID if index < 0 else self.ids[index]

    @property
    def contexts(self) -> Any:
        """The set as a batched context (None when resampling)."""
        return None if self.resamples else self.provider.contexts

    @property
    def selection_key(self) -> Hashable | None:
        """What compiled code depends on besides the set's values: the selector or the spec.

        None when that is not hashable (then nothing compiled is shared between adapters).
        """
        if self.resamples:
            key = ("resample", self.space, tuple(self.provider.spec.items()))
        else:
            key = ("set", self.space, self.provider.selector)
        try:
            hash(key)
        except TypeError:
            return None
        return key

    def visible_features(self, features: None | str | Sequence[str]) -> None | str | Sequence[str]:
        """Resolve "varying" for a distribution spec (the features it does not hold constant)."""
        if features == "varying" and self.resamples:
            return [name for name, d in self.provider.spec.items() if not isinstance(d, Constant)]
        return features

    def observation(
        self, features: None | str | Sequence[str], normalize: bool, noise: float
    ) -> ContextObservation:
        """The context observation for this schedule (``"varying"`` reads the set or the spec)."""
        contexts = None if self.resamples else self.provider.contexts
        return ContextObservation.build(
            self.space,
            self.visible_features(features),
            contexts=contexts,
            normalize=normalize,
            noise=noise,
        )

    def values_dict(self, values: np.ndarray) -> dict[str, Any]:
        """Feature name → Python value for one context vector (categorical features by name)."""
        out = {}
        for (name, feature), value in zip(self.space.features.items(), values, strict=True):
            if feature.kind == "categorical":
                out[name] = feature.choices[int(value)]
            elif feature.kind == "int":
                out[name] = int(value)
            else:
                out[name] = float(str(np.float32(value)))  # 9.8, not 9.800000190734863
        return out


def _one_context(space: ContextSpace, value: Any, where: str) -> Any:
    if isinstance(value, ContextBase):
        if not isinstance(value, space.context_class):
            raise ContextError(
                f"{where}: expected a {space.context_class.__name__}, got {type(value).__name__}"
            )
        if value.batch_shape:
            raise ContextError(f"{where}: expected one context, got a batch {value.batch_shape}")
        space.check(value)
        return value
    if isinstance(value, Mapping):
        for name, entry in value.items():  # ``make`` would take a list as a batch of contexts
            if np.ndim(entry):
                raise ContextError(
                    f"{where}: {name} takes one value per context, got {len(entry)}; "
                    "list one dict per context instead"
                )
        return space.make(**value)
    raise ContextError(
        f"{where}: expected a dict of feature values or a {space.context_class.__name__}, "
        f"got {type(value).__name__}"
    )


def _is_context_like(value: Any) -> bool:
    return isinstance(value, (ContextBase, Mapping))


def resolve_contexts(
    space: ContextSpace, contexts: Any = None, selector: str | Callable | None = None
) -> ContextSchedule:
    """Validate ``contexts`` and ``selector`` and build the schedule; raise ContextError on bad input.

    ``contexts`` may be None (the default context), one context (a dict of feature values or a context
    object), a batch of contexts (``crl.sample``), a mapping id → context, a list of contexts, or a dict
    of distributions resampled at every reset. ``selector`` ("round_robin" by default, "random",
    "static", or ``fn(key, episode, n) -> index``) picks from a set; ``episode`` is the global episode
    index ``copy + e * num_copies``.
    """
    if contexts is None:
        contexts = space.default()
    if isinstance(contexts, Mapping) and not contexts:
        raise ContextError("contexts is an empty mapping; give at least one context")
    if isinstance(contexts, Mapping) and any(
        isinstance(v, DISTRIBUTIONS) for v in contexts.values()
    ):
        if selector not in (None, DEFAULT_SELECTOR):
            raise ContextError(
                f"context_selector={selector!r} picks from a context set, but contexts is a "
                "distribution spec (resampled at every reset); drop the selector"
            )
        return ContextSchedule(space, Resample(space, contexts), ())
    if isinstance(contexts, Mapping) and all(_is_context_like(v) for v in contexts.values()):
        ids = tuple(contexts)
        members = [_one_context(space, v, f"contexts[{k!r}]") for k, v in contexts.items()]
    elif isinstance(contexts, Mapping):
        ids, members = (0,), [_one_context(space, contexts, "contexts")]
    elif isinstance(contexts, ContextBase) and contexts.batch_shape:
        if not isinstance(contexts, space.context_class):
            raise ContextError(
                f"contexts: expected {space.context_class.__name__}, got {type(contexts).__name__}"
            )
        return ContextSchedule(
            space,
            FromSet(contexts, make_selector(selector or DEFAULT_SELECTOR)),
            tuple(range(len(contexts))),
        )
    elif isinstance(contexts, ContextBase):
        ids, members = (0,), [_one_context(space, contexts, "contexts")]
    elif isinstance(contexts, Sequence) and not isinstance(contexts, str) and contexts:
        ids = tuple(range(len(contexts)))
        members = [_one_context(space, v, f"contexts[{i}]") for i, v in enumerate(contexts)]
    else:
        raise ContextError(
            "contexts must be None, a dict of feature values, a context, a batch of contexts "
            "(crl.sample), a mapping id -> context, a non-empty list of contexts, or a dict of "
            f"distributions; got {contexts!r}"
        )
    batch = space.stack(members)
    return ContextSchedule(space, FromSet(batch, make_selector(selector or DEFAULT_SELECTOR)), ids)
