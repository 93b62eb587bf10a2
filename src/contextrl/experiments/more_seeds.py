"""More seeds for a run: its finished chunks stay, renumbered to the larger plan's.

A trial's key comes from the base seed and the trial's id, and the context sets from the base seed, so
the trials a run with more seeds shares with it are exactly the ones it finished. Adding seeds therefore
gives the run a fresh one with the larger count would give, for the cost of the new seeds only. The
count must come from a rule fixed before the results were seen (the paper catalogue's scales): seeds
added because an interval looked close to a bound make its coverage optimistic.

The renumbering is journaled (``adding-seeds.json``) and finished by :func:`finish_adding_seeds`, which
every resume calls first, so a run killed part-way through is completed, not corrupted.
"""

from __future__ import annotations

import dataclasses
import json
import os

import jax
import numpy as np
import yaml

from contextrl.experiments.plan import Plan, expand
from contextrl.experiments.runs import RunDir, write_text
from contextrl.experiments.spec import CommonSpec, SpecError, spec_to_dict

JOURNAL = "adding-seeds.json"
CHUNK_FILES = (("results", "parquet"), ("curves", "parquet"), ("training", "parquet"))


def add_seeds(run: RunDir, seeds: int) -> None:
    """Raise ``run``'s seed count to ``seeds``; refused, before anything moves, where a kept chunk
    would not be a chunk of the larger plan with the same contexts, or where a chunk failed (retry
    it first). The larger plan keeps the run's batch size, or, where its chunks would regroup
    there, takes the size of the run's largest chunk: a batch size at least the seed count put all
    of a variant's seeds in one chunk, which then stays whole, the new seeds in chunks after it."""
    old = run.spec()
    if not isinstance(seeds, int) or isinstance(seeds, bool) or seeds <= old.seeds:
        raise SpecError(f"seeds: {seeds!r} for {run.path}; give an integer above its {old.seeds}")
    if run.failures():
        raise SpecError(
            f"{run.path}: a chunk failed; resume the run to retry it before adding seeds"
        )
    new, moves = _renumbering(run, old, seeds)
    timings = run.timings()
    journal = {
        "spec": spec_to_dict(new),
        "moves": moves,
        "timings": {str(j): timings[str(i)] for i, j in moves if str(i) in timings},
        "renamed": False,
    }
    write_text(run.path / JOURNAL, json.dumps(journal, indent=2))
    finish_adding_seeds(run)


def _renumbering(run: RunDir, old: CommonSpec, seeds: int) -> tuple[CommonSpec, list[list[int]]]:
    """The larger spec and, per finished chunk, [its index, its index in the larger plan]: with the
    run's batch size, else with its largest chunk's; the first size's refusal where neither fits."""
    old_plan = expand(old)
    largest = max((len(chunk) for chunk in old_plan.chunks), default=old.batch_size)
    refusals = []
    for batch_size in dict.fromkeys((old.batch_size, largest)):
        new = dataclasses.replace(old, seeds=seeds, batch_size=batch_size)
        try:
            new_plan = expand(new)
            return new, [
                [i, _same_chunk(old_plan, new_plan, i, run)] for i in sorted(run.finished())
            ]
        except SpecError as refusal:
            refusals.append(refusal)
    raise refusals[0]


def _same_chunk(old: Plan, new: Plan, index: int, run: RunDir) -> int:
    """The larger plan's index of ``old``'s chunk ``index``: the same trials on the same contexts."""
    ids = [old.trials[t].id for t in old.chunks[index]]
    same = [j for j, chunk in enumerate(new.chunks) if [new.trials[t].id for t in chunk] == ids]
    larger = f"the plan with {new.spec.seeds} seeds"
    if not same:
        raise SpecError(
            f"{run.path}: chunk {index} ({', '.join(ids)}) is not a chunk of {larger} (batch_size "
            f"{new.spec.batch_size} regroups its trials); start a new run with that count"
        )
    if not all(_same_contexts(old, new, old.trials[t]) for t in old.chunks[index]):
        raise SpecError(
            f"{run.path}: chunk {index}'s contexts differ in {larger}; start a new run with that count"
        )
    return same[0]


def _same_contexts(old: Plan, new: Plan, trial) -> bool:
    names = {trial.train_set, trial.test_set, trial.template}
    return all(
        all(
            np.array_equal(a, b)
            for a, b in zip(
                jax.tree_util.tree_leaves(old.sets[name].contexts),
                jax.tree_util.tree_leaves(new.sets[name].contexts),
                strict=True,
            )
        )
        for name in names
    )


def finish_adding_seeds(run: RunDir) -> None:
    """Complete the renumbering a journal records, wherever it stopped: first every moved chunk's files
    to names no chunk has (then the journal says so), then to their new numbers, then the timings and
    the spec; the journal goes last."""
    file = run.path / JOURNAL
    if not file.exists():
        return
    journal = json.loads(file.read_text())
    moves = [(i, j) for i, j in journal["moves"] if i != j]
    if not journal["renamed"]:
        for i, j in moves:
            for folder, suffix in CHUNK_FILES:
                source = run.path / folder / f"chunk-{i:04d}.{suffix}"
                if source.exists():
                    os.replace(source, run.path / folder / f"moving-{j:04d}.{suffix}")
        journal["renamed"] = True
        write_text(file, json.dumps(journal, indent=2))
    for _, j in moves:
        for folder, suffix in CHUNK_FILES:
            moving = run.path / folder / f"moving-{j:04d}.{suffix}"
            if moving.exists():
                os.replace(moving, run.path / folder / f"chunk-{j:04d}.{suffix}")
    write_text(run.path / "timings.json", json.dumps(journal["timings"], indent=2))
    write_text(run.path / "spec.yaml", yaml.safe_dump(journal["spec"], sort_keys=False))
    file.unlink()
