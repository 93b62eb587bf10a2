"""Protocols expand a spec into named context sets and a grid of trials (seed × variant × train set).

Everything here is deterministic in the spec: contexts are drawn from keys derived from ``spec.seed``,
so a resumed run rebuilds exactly the same plan. Trials that share a variant and set shapes are packed
into *chunks* that train in one vmapped call; a chunk is also the unit that is written, resumed and
sent to a Ray worker.
"""

from __future__ import annotations

import dataclasses
import zlib
from collections.abc import Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.distributions import draw
from contextrl.experiments.spec import (
    CommonSpec,
    OptimalityGapSpec,
    SensitivitySpec,
    TrainTestSpec,
    VisibilitySpec,
)

TRAIN_KEY, TEST_KEY = 1_000_001, 1_000_002
REGIONS = ("interpolation", "combinatorial", "extrapolation (one)", "extrapolation (both)")


@dataclasses.dataclass(frozen=True)
class ContextSet:
    """A batch of contexts with per-context labels (feature, magnitude, region…) for the results."""

    name: str
    contexts: Any
    labels: Mapping[str, Sequence[Any]] = dataclasses.field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.contexts)


@dataclasses.dataclass(frozen=True)
class Trial:
    """One agent: trained on ``train_set`` with ``variant`` and ``seed``, evaluated on ``test_set``."""

    id: str
    kind: str
    variant: str
    seed: int
    train_set: str
    test_set: str
    template_set: str = ""  # set whose varying features the agent sees (default: train_set)

    @property
    def template(self) -> str:
        return self.template_set or self.train_set

    def group(self, plan: Plan) -> tuple:
        """Trials with equal groups can be vmapped together."""
        return (
            self.variant,
            self.template,
            len(plan.sets[self.train_set]),
            len(plan.sets[self.test_set]),
        )


@dataclasses.dataclass(frozen=True)
class Plan:
    """The expanded experiment: context sets, trials and their chunks (lists of trial indices)."""

    spec: CommonSpec
    sets: dict[str, ContextSet]
    trials: list[Trial]
    chunks: list[list[int]]


def trial_key(seed: int, trial_id: str):
    """The training/evaluation key of a trial: from the base seed and the trial's id only."""
    return jax.random.fold_in(jax.random.key(seed), zlib.crc32(trial_id.encode()) & 0x7FFFFFFF)


def _draw(spec: CommonSpec, field: str, features: Mapping, n: int, stream: int):
    space = spec.space()
    resolved = spec.resolve_features(field, features)
    return draw(space, resolved, n, jax.random.fold_in(jax.random.key(spec.seed), stream))


def _chunks(plan_trials: list[Trial], sets: dict[str, ContextSet], size: int) -> list[list[int]]:
    groups: dict[tuple, list[int]] = {}
    stub = Plan(None, sets, plan_trials, [])  # type: ignore[arg-type]
    for index, trial in enumerate(plan_trials):
        groups.setdefault(trial.group(stub), []).append(index)
    return [
        members[i : i + size] for members in groups.values() for i in range(0, len(members), size)
    ]


def _grid(spec: CommonSpec, kind: str, train_set: str, test_set: str) -> list[Trial]:
    return [
        Trial(f"{kind}-{variant}-s{seed}", kind, variant, seed, train_set, test_set)
        for variant in spec.variants
        for seed in range(spec.seeds)
    ]


def sensitivity(spec: SensitivitySpec) -> tuple[dict, list]:
    space = spec.space()
    default = space.default()
    contexts, feature_labels, magnitudes = [], [], []
    for name in spec.feature_names():
        f = space.features[name]
        for magnitude in spec.magnitudes:
            value = magnitude * f.default
            if f.kind == "int":
                value = round(value)
            if not f.lower <= value <= f.upper:
                continue  # outside the feature's declared bounds: not a valid environment
            contexts.append(default.replace(**{name: value}))
            feature_labels.append(name)
            magnitudes.append(float(magnitude))
    sets = {
        "default": ContextSet("default", space.stack([default])),
        "scaled": ContextSet(
            "scaled", space.stack(contexts), {"feature": feature_labels, "magnitude": magnitudes}
        ),
    }
    return sets, _grid(spec, "default", "default", "scaled")


def optimality_gap(spec: OptimalityGapSpec) -> tuple[dict, list]:
    train = _draw(spec, "train", spec.train, spec.num_contexts, TRAIN_KEY)
    ids = list(range(spec.num_contexts))
    sets = {"train": ContextSet("train", train, {"context": ids})}
    trials = _grid(spec, "general", "train", "train")
    for i in ids:
        name = f"train[{i}]"
        sets[name] = ContextSet(name, train[i : i + 1], {"context": [i]})
        trials += [
            Trial(
                f"specialist{i}-{variant}-s{seed}", "specialist", variant, seed, name, name, "train"
            )
            for variant in spec.variants
            for seed in range(spec.seeds)
        ]
    return sets, trials


def visibility(spec: VisibilitySpec) -> tuple[dict, list]:
    train = _draw(spec, "train", spec.train, spec.num_train_contexts, TRAIN_KEY)
    test = _draw(
        spec,
        "test" if spec.test else "train",
        spec.test or spec.train,
        spec.num_test_contexts,
        TEST_KEY,
    )
    sets = {"train": ContextSet("train", train), "test": ContextSet("test", test)}
    return sets, _grid(spec, "visibility", "train", "test")


def region_of(
    point: Sequence[float], train_box: Sequence[tuple[float, float]], mode: str, band: float
):
    """Kirk et al.'s region of a test context relative to a training set of ``mode``."""
    inside = [low <= v <= high for v, (low, high) in zip(point, train_box, strict=True)]
    if not any(inside):
        return REGIONS[3]
    if not all(inside):
        return REGIONS[2]
    if mode == "A":
        return REGIONS[0]
    width = [band * (high - low) if mode == "B" else 0.0 for low, high in train_box]
    on_support = any(v <= low + w for v, (low, _), w in zip(point, train_box, width, strict=True))
    return REGIONS[0] if on_support else REGIONS[1]


def train_test_contexts(spec: TrainTestSpec, mode: str, key) -> Any:
    """Training contexts of one mode; every draw is direct (no rejection loop), so it always ends."""
    train_box, _ = spec.boxes()
    space = spec.space()
    (name_x, (x0, x1)), (name_y, (y0, y1)) = train_box.items()
    n = spec.num_train_contexts
    keys = jax.random.split(key, 4)
    x = jax.random.uniform(keys[0], (n,), minval=x0, maxval=x1)
    y = jax.random.uniform(keys[1], (n,), minval=y0, maxval=y1)
    if mode != "A":
        # An L-shaped set: half the contexts on the low-x edge band, half on the low-y edge band.
        fraction = spec.band if mode == "B" else 0.0
        on_x_edge = jax.random.bernoulli(keys[2], 0.5, (n,))
        thin_x = x0 + fraction * (x1 - x0) * jax.random.uniform(keys[3], (n,))
        thin_y = y0 + fraction * (y1 - y0) * jax.random.uniform(keys[3], (n,))
        x = jnp.where(on_x_edge, thin_x, x)
        y = jnp.where(on_x_edge, y, thin_y)
    defaults = draw(space, {}, n, key)
    return defaults.replace(**{name_x: np.asarray(x), name_y: np.asarray(y)})


def train_test(spec: TrainTestSpec) -> tuple[dict, list]:
    train_box, test_box = spec.boxes()
    space = spec.space()
    (name_x, (sx0, sx1)), (name_y, (sy0, sy1)) = test_box.items()
    side = int(np.floor(np.sqrt(spec.num_test_contexts)))
    gx, gy = np.meshgrid(np.linspace(sx0, sx1, side), np.linspace(sy0, sy1, side), indexing="ij")
    test = draw(space, {}, gx.size, jax.random.key(0)).replace(
        **{name_x: gx.ravel().astype(np.float32), name_y: gy.ravel().astype(np.float32)}
    )
    sets = {}
    trials = []
    boxes = list(train_box.values())
    for mode in spec.modes:
        key = jax.random.fold_in(jax.random.key(spec.seed), TRAIN_KEY + ord(mode))
        regions = [
            region_of((px, py), boxes, mode, spec.band)
            for px, py in zip(gx.ravel(), gy.ravel(), strict=True)
        ]
        sets[f"train-{mode}"] = ContextSet(f"train-{mode}", train_test_contexts(spec, mode, key))
        sets[f"test-{mode}"] = ContextSet(
            f"test-{mode}", test, {"region": regions, "mode": [mode] * len(regions)}
        )
        trials += _grid(spec, f"mode{mode}", f"train-{mode}", f"test-{mode}")
    return sets, trials


EXPANDERS = {
    "sensitivity": sensitivity,
    "optimality_gap": optimality_gap,
    "visibility": visibility,
    "train_test": train_test,
}


def expand(spec: CommonSpec) -> Plan:
    """The plan of a validated spec (the tabular protocol has no trials: it is solved exactly)."""
    if spec.protocol == "tabular":
        return Plan(spec, {}, [], [])
    sets, trials = EXPANDERS[spec.protocol](spec)
    ids = [t.id for t in trials]
    assert len(set(ids)) == len(ids), "trial ids must be unique"
    return Plan(spec, sets, trials, _chunks(trials, sets, spec.batch_size))


def stack_sets(sets: Sequence[Any]) -> Any:
    """Context batches of equal shape stacked on a new leading (trial) axis."""
    return jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *sets)
