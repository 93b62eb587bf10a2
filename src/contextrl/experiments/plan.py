"""What every protocol expands into: named context sets and a grid of trials (seed × variant × train
set), packed into chunks. Each protocol's own expansion lives in its module (``Protocol.expand``).

Everything here is deterministic in the spec: contexts are drawn from keys derived from ``spec.seed``,
so a resumed run rebuilds exactly the same plan. Trials that share a variant and set shapes are packed
into *chunks* that train in one vmapped call; a chunk is also the unit that is written, resumed and
sent to a Ray worker. A plan's :func:`outline` (its sets' sizes, trials and chunks) counts steps and
chunks without drawing a context.
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
from contextrl.experiments.protocol import protocol_of
from contextrl.experiments.spec import CommonSpec

TRAIN_KEY, TEST_KEY = 1_000_001, 1_000_002


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
    # a curriculum over train_set (the spec's make_curriculum names it; "": train on the set as is)
    curriculum: str = ""

    @property
    def template(self) -> str:
        return self.template_set or self.train_set

    def group(self, sizes: Mapping[str, int]) -> tuple:
        """Trials with equal groups can be vmapped together (``sizes``: each set's contexts)."""
        return (
            self.variant,
            self.template,
            sizes[self.train_set],
            sizes[self.test_set],
            self.curriculum,
        )


@dataclasses.dataclass(frozen=True)
class Plan:
    """The expanded experiment: context sets, trials and their chunks (lists of trial indices)."""

    spec: CommonSpec
    sets: dict[str, ContextSet]
    trials: list[Trial]
    chunks: list[list[int]]

    @property
    def sizes(self) -> dict[str, int]:
        """The number of contexts in each set."""
        return {name: len(s) for name, s in self.sets.items()}


@dataclasses.dataclass(frozen=True)
class Outline:
    """A plan without its contexts: each set's size, the trials and their chunks, as
    :func:`expand` gives them (what counting steps and chunks needs)."""

    spec: CommonSpec
    sizes: dict[str, int]
    trials: list[Trial]
    chunks: list[list[int]]


TRIAL_COLUMNS = ("trial", "kind", "variant", "seed", "train_set")


def trial_columns(trial: Trial) -> dict[str, Any]:
    """The columns that name a trial in every results table (results, evaluations, absent rows)."""
    values = (trial.id, trial.kind, trial.variant, trial.seed, trial.train_set)
    return dict(zip(TRIAL_COLUMNS, values, strict=True))


def context_columns(test: ContextSet, names: Sequence[str]) -> dict[str, Any]:
    """The columns that name each context of ``test`` in a results table: the set, the index in it,
    every feature (``ctx.NAME``) and the set's labels."""
    return {
        "test_set": test.name,
        "context_index": np.arange(len(test)),
        **{f"ctx.{n}": np.asarray(getattr(test.contexts, n)) for n in names},
        **{k: list(v) for k, v in test.labels.items()},
    }


def trial_key(seed: int, trial_id: str):
    """The training/evaluation key of a trial: from the base seed and the trial's id only."""
    return jax.random.fold_in(jax.random.key(seed), zlib.crc32(trial_id.encode()) & 0x7FFFFFFF)


def draw_set(spec: CommonSpec, field: str, features: Mapping, n: int, stream: int):
    space = spec.space()
    resolved = spec.resolve_features(field, features)
    return draw(space, resolved, n, jax.random.fold_in(jax.random.key(spec.seed), stream))


def train_and_test_sizes(spec: CommonSpec) -> dict[str, int]:
    """The sizes of :func:`train_and_test_sets`' sets."""
    return {"train": spec.num_train_contexts, "test": spec.num_test_contexts}


def train_and_test_sets(spec: CommonSpec) -> dict[str, ContextSet]:
    """The ``train`` set (``num_train_contexts`` drawn from ``spec.train``) and the ``test`` set
    (``num_test_contexts`` from ``spec.test``, or from ``spec.train`` where it gives none), each
    drawn from its own key stream."""
    train = draw_set(spec, "train", spec.train, spec.num_train_contexts, TRAIN_KEY)
    test = draw_set(
        spec,
        "test" if spec.test else "train",
        spec.test or spec.train,
        spec.num_test_contexts,
        TEST_KEY,
    )
    return {"train": ContextSet("train", train), "test": ContextSet("test", test)}


def _chunks(plan_trials: list[Trial], sizes: Mapping[str, int], size: int) -> list[list[int]]:
    groups: dict[tuple, list[int]] = {}
    for index, trial in enumerate(plan_trials):
        groups.setdefault(trial.group(sizes), []).append(index)
    return [
        members[i : i + size] for members in groups.values() for i in range(0, len(members), size)
    ]


def grid(spec: CommonSpec, kind: str, train_set: str, test_set: str) -> list[Trial]:
    return [
        Trial(f"{kind}-{variant}-s{seed}", kind, variant, seed, train_set, test_set)
        for variant in spec.variants
        for seed in range(spec.seeds)
    ]


def expand(spec: CommonSpec) -> Plan:
    """The plan of a validated spec (empty for a protocol that trains no agents)."""
    if not spec.trains_agents:
        return Plan(spec, {}, [], [])
    protocol = protocol_of(spec)
    sets, trials = protocol.expand(spec)
    ids = [t.id for t in trials]
    assert len(set(ids)) == len(ids), "trial ids must be unique"
    sizes = {name: len(s) for name, s in sets.items()}
    if protocol.outline is not None:  # the counts read without drawing are this plan's
        assert protocol.outline(spec) == (sizes, trials), f"{spec.protocol}: outline ≠ expansion"
    return Plan(spec, sets, trials, _chunks(trials, sizes, spec.batch_size))


def outline(spec: CommonSpec) -> Outline:
    """What :func:`expand` plans, without drawing a context: each set's size, the trials and their
    chunks (from the protocol's ``outline``; expanded where it has none)."""
    if not spec.trains_agents:
        return Outline(spec, {}, [], [])
    protocol = protocol_of(spec)
    if protocol.outline is None:
        plan = expand(spec)
        return Outline(spec, plan.sizes, plan.trials, plan.chunks)
    sizes, trials = protocol.outline(spec)
    return Outline(spec, sizes, trials, _chunks(trials, sizes, spec.batch_size))


def stack_sets(sets: Sequence[Any]) -> Any:
    """Context batches of equal shape stacked on a new leading (trial) axis."""
    return jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *sets)
