"""Contexts that change within an episode, along a declared schedule.

A change is checked against the environment once, when it is bound (``ContextualEnv(..., changes=)``):
its features must exist, its parameters be finite and of the right type, and each feature must be one
whose change can act mid-episode. The core then calls :meth:`apply` on every step (pure, jittable):
step ``t`` of an episode (1, 2, …) runs under ``apply(key, t, context)``, where ``context`` is the one
step ``t - 1`` ran under (the episode's start context for step 1) and ``key`` is that step's key.

Four kinds: :class:`Redraw` (every N steps a fresh draw from a distribution spec), :class:`RandomWalk`
(a bounded random walk per feature), :class:`Piecewise` (values from given steps on) and
:class:`StepFunction` (``fn(step, context) -> context``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.distributions import check_spec
from contextrl.context.features import ContextError, ContextSpace

# What an environment builds from these features, which a change mid-episode would rebuild under the
# agent; their declared effects cannot say so (environment name → feature → why).
BUILT_FROM = {
    "Platformer": {
        **dict.fromkeys(
            (
                "level_width",
                "level_index",
                "noise_seed",
                "gap_width",
                "gap_frequency",
                "enemy_density",
                "platform_height_variation",
            ),
            "it sets the level's layout, which a change would rebuild around the agent",
        ),
        **dict.fromkeys(
            ("mario_inertia", "gravity", "jump_speed", "run_speed"),
            "the level's gaps, steps and pipes are sized from it, so a change would rebuild the "
            "layout around the agent",
        ),
        "mario_state": "it is the form the agent starts in (hits lower it during the episode)",
    },
}


def why_fixed(env, name: str) -> str | None:
    """Why feature ``name`` of ``env`` cannot change mid-episode, or None when it can."""
    built_from = BUILT_FROM.get(env.name, {})
    if name in built_from:
        return built_from[name]
    if env.context_space.features[name].affects == ("start_state",):
        return "it sets only the start state, which is drawn at reset"
    return None


def changeable(env) -> list[str]:
    """The features of ``env`` that a change may move mid-episode."""
    return [name for name in env.context_space.names if why_fixed(env, name) is None]


def _features(env, names, kind: str) -> list[str]:
    """``names`` resolved to canonical features of ``env``, each one that may change mid-episode."""
    space = env.context_space
    if isinstance(names, (str, bytes)) or not names:
        raise ContextError(f"{kind}: expected feature names, got {names!r}")
    resolved = []
    for name in names:
        try:
            canonical = space.resolve(name)
        except ContextError as error:
            raise ContextError(f"{kind}: {error}") from None
        why = why_fixed(env, canonical)
        if why is not None:
            allowed = changeable(env)
            can = f"features that can: {allowed}" if allowed else f"no feature of {env.name} can"
            raise ContextError(
                f"{kind}: {env.name}'s feature {canonical!r} cannot change mid-episode: {why}; "
                + can
            )
        resolved.append(canonical)
    return resolved


def _number(kind: str, what: str, value) -> float:
    """``value`` as a finite float, refused with its parameter's name otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ContextError(f"{kind}: {what} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ContextError(f"{kind}: {what} must be finite, got {value!r}")
    return float(value)


def _positive_steps(kind: str, what: str, value) -> int:
    """``value`` as a count of steps (an integer >= 1), refused with its parameter's name otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ContextError(f"{kind}: {what} must be a positive integer of steps, got {value!r}")
    return int(value)


def _mapping(kind: str, what: str, value) -> Mapping:
    """``value`` if it is a non-empty mapping, refused with its parameter's name otherwise."""
    if not isinstance(value, Mapping) or not value:
        raise ContextError(f"{kind}: {what} must be a non-empty mapping, got {value!r}")
    return value


@dataclasses.dataclass(frozen=True)
class Redraw:
    """Every ``every`` steps (steps N, 2N, …), the features of ``spec`` drawn afresh from its
    distributions (those of :mod:`contextrl.context.distributions`; a plain number is a constant)."""

    every: int
    spec: Mapping[str, Any]
    uses_key: ClassVar[bool] = True  # the core derives a key for its draws only when asked

    def bind(self, env) -> Redraw:
        every = _positive_steps("Redraw", "every", self.every)
        spec = _mapping("Redraw", "spec", self.spec)
        _features(env, list(spec), "Redraw")
        try:
            resolved = check_spec(env.context_space, spec)
        except ContextError as error:
            raise ContextError(f"Redraw: spec: {error}") from None
        return Redraw(every, resolved)

    def apply(self, key, step, context):
        space = context.space
        drawn = {
            name: distribution.sample(_feature_key(space, key, name), 1, space.features[name])[0]
            for name, distribution in self.spec.items()
        }
        due = step % self.every == 0
        return _replaced(
            space, context, {n: jnp.where(due, v, getattr(context, n)) for n, v in drawn.items()}
        )


@dataclasses.dataclass(frozen=True)
class RandomWalk:
    """Every step, each float feature of ``step_size`` moves by a normal increment of that standard
    deviation, clipped to ``ranges[feature]`` (default: the feature's declared bounds)."""

    step_size: Mapping[str, float]
    ranges: Mapping[str, tuple[float, float]] = dataclasses.field(default_factory=dict)
    uses_key: ClassVar[bool] = True

    def bind(self, env) -> RandomWalk:
        space = env.context_space
        step_size = _mapping("RandomWalk", "step_size", self.step_size)
        if not isinstance(self.ranges, Mapping):
            raise ContextError(f"RandomWalk: ranges must be a mapping, got {self.ranges!r}")
        names = _features(env, list(step_size), "RandomWalk")
        sizes, ranges = {}, {}
        for given, name in zip(step_size, names, strict=True):
            f = space.features[name]
            if f.kind != "float":
                raise ContextError(
                    f"RandomWalk: {name} is {f.kind}; a random walk moves float features only "
                    f"(use Redraw or Piecewise for it)"
                )
            size = _number("RandomWalk", f"step_size[{given!r}]", step_size[given])
            if size <= 0:
                raise ContextError(f"RandomWalk: step_size[{given!r}] must be > 0, got {size:g}")
            sizes[name] = size
            ranges[name] = f.bounds
        for given, bounds in self.ranges.items():
            name = space.resolve(given)
            if name not in sizes:
                raise ContextError(
                    f"RandomWalk: ranges[{given!r}] names a feature that does not walk; "
                    f"walking: {list(sizes)}"
                )
            low, high = _range("RandomWalk", f"ranges[{given!r}]", bounds)
            f = space.features[name]
            if not f.lower <= low <= high <= f.upper:
                raise ContextError(
                    f"RandomWalk: ranges[{given!r}] = [{low:g}, {high:g}] must be a non-empty range "
                    f"inside {name}'s bounds [{f.lower:g}, {f.upper:g}]"
                )
            ranges[name] = (low, high)
        space.check_ranges(ranges, "this random walk")
        return RandomWalk(sizes, ranges)

    def apply(self, key, step, context):
        space = context.space
        moved = {}
        for name, size in self.step_size.items():
            increment = size * jax.random.normal(_feature_key(space, key, name))
            low, high = self.ranges[name]
            moved[name] = jnp.clip(getattr(context, name) + increment, low, high)
        return _replaced(space, context, moved)


@dataclasses.dataclass(frozen=True)
class Piecewise:
    """Feature values from given steps on: ``{50: {"gravity": 12.0}, 100: {"gravity": 9.8}}`` runs
    steps 50–99 under gravity 12 and steps from 100 on under 9.8 (before 50: the episode's own)."""

    values: Mapping[int, Mapping[str, Any]]
    uses_key: ClassVar[bool] = False

    def bind(self, env) -> Piecewise:
        space = env.context_space
        given = _mapping("Piecewise", "values", self.values)
        starts = {_positive_steps("Piecewise", "a key of values", s): s for s in given}
        pieces = {}
        for start in sorted(starts):
            piece = _mapping("Piecewise", f"values[{start}]", given[starts[start]])
            names = _features(env, list(piece), "Piecewise")
            coerced = {}
            for name, value in zip(names, piece.values(), strict=True):
                try:
                    coerced[name] = space.features[name].coerce(value)
                except ContextError as error:
                    raise ContextError(f"Piecewise: values[{start}]: {error}") from None
            pieces[start] = coerced
        reached: dict[str, list[float]] = {}
        for piece in pieces.values():
            for name, value in piece.items():
                reached.setdefault(name, []).append(float(value))
        space.check_ranges({n: (min(v), max(v)) for n, v in reached.items()}, "this schedule")
        return Piecewise(pieces)

    def apply(self, key, step, context):
        space = context.space
        for start, piece in self.values.items():  # in order of their steps: a later piece wins
            values = {n: jnp.where(step >= start, v, getattr(context, n)) for n, v in piece.items()}
            context = _replaced(space, context, values)
        return context


@dataclasses.dataclass(frozen=True)
class StepFunction:
    """``fn(step, context) -> context``, traced at every step with the context the previous step ran
    under, for the features named in ``features`` (clipped to their bounds; the others keep their
    values whatever ``fn`` returns)."""

    fn: Callable[[jax.Array, Any], Any]
    features: tuple[str, ...]
    uses_key: ClassVar[bool] = False

    def bind(self, env) -> StepFunction:
        if not callable(self.fn):
            raise ContextError(f"StepFunction: fn must be callable, got {self.fn!r}")
        return StepFunction(self.fn, tuple(_features(env, self.features, "StepFunction")))

    def apply(self, key, step, context):
        result = self.fn(step, context)
        space = context.space
        if not isinstance(result, space.context_class):
            raise ContextError(
                f"StepFunction: fn must return a {space.context_class.__name__}, "
                f"got {type(result).__name__}"
            )
        bounded = {
            n: jnp.clip(getattr(result, n), *space.features[n].bounds) for n in self.features
        }
        return _replaced(space, context, bounded)


Change = Redraw | RandomWalk | Piecewise | StepFunction
CHANGES = (Redraw, RandomWalk, Piecewise, StepFunction)


def bind(env, changes: Change):
    """``changes`` checked against ``env``: names resolved, parameters validated, features allowed."""
    if not isinstance(changes, CHANGES):
        raise ContextError(
            f"changes must be one of {[c.__name__ for c in CHANGES]}, got {type(changes).__name__}"
        )
    return changes.bind(env)


def _range(kind: str, what: str, bounds) -> tuple[float, float]:
    """``bounds`` as a pair of finite floats, refused with its parameter's name otherwise."""
    if isinstance(bounds, (str, bytes)) or np.shape(bounds) != (2,):
        raise ContextError(f"{kind}: {what} must be a pair (low, high), got {bounds!r}")
    low, high = (_number(kind, what, v) for v in bounds)
    return low, high


def _feature_key(space: ContextSpace, key, name: str):
    """The key of one feature's draw: folded in by its declaration index, as :func:`sample` does."""
    return jax.random.fold_in(key, space.names.index(name))


def _replaced(space: ContextSpace, context, values: Mapping[str, Any]):
    """``context`` with traced ``values`` at their features' dtypes (no validation: already checked)."""
    cast = {n: jnp.asarray(v, space.features[n].dtype) for n, v in values.items()}
    return dataclasses.replace(context, **cast)
