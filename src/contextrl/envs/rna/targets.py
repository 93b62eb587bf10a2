"""RNA design targets: the shipped data sets, user files in the same format, and a seeded generator.

A data set is a plain text file with one dot-bracket structure per line; line i is target id i
(1-based). Eterna100 v1 and v2 (MIT) and Rfam-Taneda (Apache-2.0, Rfam data CC0) ship inside the
package under ``data/`` with their license notices and ``PROVENANCE.md``. ``data_dir=`` points at a
folder holding files with the same names; each file found there replaces the shipped one.

LEARNA's Rfam-Learn sets are not available offline. The ``synthetic`` data set stands in for them: target
``k`` is the minimum-free-energy structure of a random sequence drawn from a generator seeded with
``(seed, k)``, kept when enough bases pair and the structure has a multiloop (Rfam-like), so the same id
is the same target on every machine, and the sequence it came from is a known solution.
"""

from __future__ import annotations

import dataclasses
import importlib.resources
import math
from pathlib import Path

import numpy as np
import RNA

DATASETS = ("eterna100_v1", "eterna100_v2", "rfam_taneda", "synthetic")
STRUCTURE_FILES = {
    "eterna100_v1": "eterna100_v1.txt",
    "eterna100_v2": "eterna100_v2.txt",
    "rfam_taneda": "rfam_taneda.txt",
}
NAME_FILES = {"eterna100_v1": "eterna100_names.txt", "eterna100_v2": "eterna100_names.txt"}
SOLUTION_FILES = {"eterna100_v2": "eterna100_v2_sample_solutions_vienna2.txt"}
MAX_TARGETS = 65_000  # Rfam-Learn's training set size: the most targets a data set may hold
BASES = "ACGU"


class TargetError(ValueError):
    """A malformed target or solution, or a target id that a data set does not have."""


def fold(sequence: str) -> str:
    """The minimum-free-energy structure of ``sequence`` (ViennaRNA, default Turner 2004 energies)."""
    return RNA.fold(sequence)[0]


def pair_table(structure: str, where: str) -> np.ndarray:
    """``partners[i] = j`` for each base pair (i, j) and -1 where a site is unpaired.

    Raises TargetError naming ``where`` (data set and id) and the reason: an empty line, a character
    other than ``.()``, a ``)`` that closes nothing or a ``(`` never closed.
    """
    if not structure:
        raise TargetError(f"{where}: empty target (a blank line)")
    partners = np.full(len(structure), -1, np.int32)
    opened: list[int] = []
    for site, symbol in enumerate(structure):
        if symbol == "(":
            opened.append(site)
        elif symbol == ")":
            if not opened:
                raise TargetError(
                    f"{where}: unbalanced brackets: ')' at position {site + 1} closes nothing"
                )
            partner = opened.pop()
            partners[site], partners[partner] = partner, site
        elif symbol != ".":
            raise TargetError(
                f"{where}: bad character {symbol!r} at position {site + 1}; a target uses only "
                "'.', '(' and ')'"
            )
    if opened:
        raise TargetError(
            f"{where}: unbalanced brackets: '(' at position {opened[-1] + 1} is never closed"
        )
    return partners


def count_multiloops(partners: np.ndarray) -> int:
    """Loops closed by a pair that enclose two or more further pairs (branches)."""
    multiloops = 0
    for opening, closing in enumerate(partners):
        if closing <= opening:
            continue
        branches, site = 0, opening + 1
        while site < closing:
            if partners[site] > site:  # an inner pair: count it and jump over it
                branches += 1
                site = partners[site]
            site += 1
        multiloops += branches >= 2
    return multiloops


@dataclasses.dataclass(frozen=True)
class Target:
    """One target structure, its pair table, and a sequence known to fold to it (None if unknown)."""

    dataset: str
    id: int
    structure: str
    partners: np.ndarray = dataclasses.field(compare=False, repr=False)
    name: str = ""
    solution: str | None = None

    def __len__(self) -> int:
        return len(self.structure)


def _check_range(name: str, value, low: float, high: float, integer: bool) -> None:
    kinds = (int, np.integer) if integer else (int, float, np.integer, np.floating)
    if isinstance(value, bool) or not isinstance(value, kinds) or not math.isfinite(value):
        kind = "an integer" if integer else "a finite number"
        raise ValueError(f"synthetic {name}: expected {kind}, got {value!r}")
    if not low <= value <= high:
        raise ValueError(f"synthetic {name}: value {value!r} is outside its bounds [{low}, {high}]")


@dataclasses.dataclass(frozen=True)
class SyntheticTargets:
    """How the ``synthetic`` stand-in for Rfam-Learn draws target ``k`` (defaults: PROVENANCE.md).

    Target ``k`` is the MFE structure of a sequence of uniform length in ``lengths`` and uniform GC
    content in ``gc_content``, redrawn (same generator) until at least ``min_paired_fraction`` of its
    bases pair and it has ``min_multiloops`` multiloops. Short targets for quick experiments:
    ``SyntheticTargets(lengths=(12, 24), min_multiloops=0)``.
    """

    lengths: tuple[int, int] = (50, 450)
    gc_content: tuple[float, float] = (0.35, 0.65)
    min_paired_fraction: float = 0.3
    min_multiloops: int = 1
    size: int = MAX_TARGETS
    seed: int = 0
    max_attempts: int = 10_000

    def __post_init__(self):
        for name in ("lengths", "gc_content"):
            value = getattr(self, name)
            if not isinstance(value, (tuple, list)) or len(value) != 2:
                raise ValueError(f"synthetic {name}: expected (low, high), got {value!r}")
            object.__setattr__(self, name, tuple(value))
        for value in self.lengths:
            _check_range("lengths", value, 5, 10_000, True)
        for value in self.gc_content:
            _check_range("gc_content", value, 0.0, 1.0, False)
        if self.lengths[0] > self.lengths[1] or self.gc_content[0] > self.gc_content[1]:
            raise ValueError(
                f"synthetic: empty range in lengths={self.lengths} or {self.gc_content}"
            )
        _check_range("min_paired_fraction", self.min_paired_fraction, 0.0, 1.0, False)
        _check_range("min_multiloops", self.min_multiloops, 0, 1_000, True)
        _check_range("size", self.size, 1, MAX_TARGETS, True)
        _check_range("seed", self.seed, 0, 2**63 - 1, True)
        _check_range("max_attempts", self.max_attempts, 1, 10**9, True)

    def draw(self, target_id: int) -> tuple[str, str]:
        """(structure, sequence) of target ``target_id``: the same on every call and machine."""
        rng = np.random.default_rng([self.seed, target_id])
        for _ in range(self.max_attempts):
            length = int(rng.integers(self.lengths[0], self.lengths[1] + 1))
            gc = rng.uniform(*self.gc_content)
            probabilities = [(1 - gc) / 2, gc / 2, gc / 2, (1 - gc) / 2]  # A, C, G, U
            sequence = "".join(np.asarray(list(BASES))[rng.choice(4, length, p=probabilities)])
            structure = fold(sequence)
            partners = pair_table(structure, "synthetic")
            paired = float(np.mean(partners >= 0))
            if paired >= self.min_paired_fraction and (
                self.min_multiloops == 0 or count_multiloops(partners) >= self.min_multiloops
            ):
                return structure, sequence
        raise TargetError(
            f"synthetic target {target_id}: no structure passed the filters in {self.max_attempts} "
            f"draws (lengths={self.lengths}, min_paired_fraction={self.min_paired_fraction}, "
            f"min_multiloops={self.min_multiloops}); relax them"
        )


def _read_lines(name: str, folder: Path | None) -> list[str] | None:
    """The lines of a data file in ``folder`` (None: the shipped data), or None if it has none."""
    if folder is None:
        path = importlib.resources.files("contextrl.envs.rna").joinpath("data", name)
    else:
        path = folder / name
    if not path.is_file():
        return None
    return [line.strip() for line in path.read_text().splitlines()]


def _solution(line: str, target: str, where: str) -> str | None:
    """A known solution line: bases of the target's length, or ``(...)`` for none (e.g. undisclosed)."""
    if line.startswith("(") and line.endswith(")") and not set(line) <= set("()."):
        return None
    if len(line) != len(target) or not set(line) <= set(BASES):
        raise TargetError(
            f"{where}: a solution must be {len(target)} bases from {BASES!r} (or '(...)' for none), "
            f"got {line[:40]!r}"
        )
    return line


class TargetSets:
    """Every target the environment can draw, by data set name and 1-based id; parsed and checked once."""

    def __init__(
        self, data_dir: str | Path | None = None, synthetic: SyntheticTargets | None = None
    ):
        self.data_dir = None if data_dir is None else Path(data_dir)
        if self.data_dir is not None:
            known = sorted(STRUCTURE_FILES.values())
            if not self.data_dir.is_dir():
                raise TargetError(f"data_dir {str(self.data_dir)!r} is not a directory")
            if not any((self.data_dir / name).is_file() for name in known):
                raise TargetError(
                    f"data_dir {str(self.data_dir)!r} holds none of the target files {known}"
                )
        self.synthetic = SyntheticTargets() if synthetic is None else synthetic
        self._files = {name: self._load(name) for name in STRUCTURE_FILES}
        self._generated: dict[int, Target] = {}

    def _load(self, dataset: str) -> list[Target]:
        """A data set's targets, with names and solutions from the same folder (where it has them)."""
        folder = self.data_dir
        structures = _read_lines(STRUCTURE_FILES[dataset], folder)
        if structures is None:  # not in data_dir: the shipped data set, whole
            folder = None
            structures = _read_lines(STRUCTURE_FILES[dataset], folder)
        if len(structures) > MAX_TARGETS:
            raise TargetError(
                f"{dataset}: {len(structures)} targets; a data set holds at most {MAX_TARGETS}"
            )
        names = _read_lines(NAME_FILES[dataset], folder) if dataset in NAME_FILES else None
        solutions = (
            _read_lines(SOLUTION_FILES[dataset], folder) if dataset in SOLUTION_FILES else None
        )
        for kind, lines in (("names", names), ("solutions", solutions)):
            if lines and len(lines) != len(structures):
                raise TargetError(
                    f"{dataset}: {len(lines)} {kind} for {len(structures)} targets; give one per line"
                )
        targets = []
        for index, structure in enumerate(structures):
            where = f"{dataset} target {index + 1}"
            partners = pair_table(structure, where)
            solution = _solution(solutions[index], structure, where) if solutions else None
            name = names[index] if names else ""
            targets.append(Target(dataset, index + 1, structure, partners, name, solution))
        return targets

    def size(self, dataset: str) -> int:
        """How many targets ``dataset`` holds (ids 1 … size)."""
        if dataset == "synthetic":
            return self.synthetic.size
        return len(self._files[dataset])

    def get(self, dataset: str, target_id: int) -> Target:
        """Target ``target_id`` of ``dataset``; TargetError naming the id when it is out of range."""
        if dataset not in DATASETS:
            raise TargetError(f"unknown data set {dataset!r}; choose one of {list(DATASETS)}")
        size = self.size(dataset)
        if not 1 <= target_id <= size:
            raise TargetError(
                f"target id {target_id} is out of range: data set {dataset} has ids 1..{size}"
            )
        if dataset == "synthetic":
            return self._synthetic(target_id)
        return self._files[dataset][target_id - 1]

    def _synthetic(self, target_id: int) -> Target:
        """A generated target, drawn once and remembered (drawing folds until the filters pass; a
        remembered target of n nt holds about 5n bytes)."""
        if target_id not in self._generated:
            structure, sequence = self.synthetic.draw(target_id)
            partners = pair_table(structure, f"synthetic target {target_id}")
            self._generated[target_id] = Target(
                "synthetic", target_id, structure, partners, "", sequence
            )
        return self._generated[target_id]

    @property
    def max_length(self) -> int:
        """The longest target any data set can give (synthetic: its upper length)."""
        lengths = [len(t) for targets in self._files.values() for t in targets]
        return max([*lengths, self.synthetic.lengths[1]])
