"""RnaDesign: the LEARNA task (Runge et al. 2019) as a contextual host environment on ViennaRNA.

Given a target secondary structure in dot-bracket notation, the agent writes an RNA sequence left to
right. At an unpaired site it places one base (A, C, G or U: four actions); at the opening site of a
pair it places a Watson–Crick pair (AU, CG, GC or UA), which fills the closing site too (closing
sites are never visited). When the sequence is complete it is folded (ViennaRNA's minimum free
energy structure) and the episode ends with reward ``(1 − d/n)^reward_exponent`` for the Hamming
distance d between the folded and the target structure of length n. When ``0 < d < mutation_threshold``
(strict, as LEARNA), LEARNA's local improvement runs first: every A/C/G/U combination at the d
mismatched sites is folded (each site on its own: a paired site's partner is left as it is) and the
design with the smallest distance is kept, stopping at d = 0. The strict bound is what keeps it
affordable: 4^d − 1 folds at distance d (a threshold above ``MAX_EXHAUSTIVE_THRESHOLD`` is refused
unless ``improvement_folds`` sets a budget).

Which target an episode designs: the context names a data set (``dataset``) and a range of its
1-based ids (``target_id_first`` … ``target_id_last``, 0 meaning its last id). As LEARNA, the range's
ids are shuffled once per epoch and taken in that order, the order drawn from the generator
``reset(seed=...)`` seeds (a new generator starts new epochs); each range of a context set keeps its
own epoch. A context set over id ranges gives train/test splits, and a set of single-id contexts
(first = last) any list of ids.

Our extensions, off by default (LEARNA's task is the default): ``wobble_pairs=True`` adds the GU and
UG pairs as actions 4 and 5 (at an unpaired site they place G and U again, so a uniform policy puts
G and U there with probability 1/3 each); ``improvement="random"`` replaces the exhaustive search by
a seeded random search that also re-pairs mismatched paired sites; ``improvement_folds`` caps the
folds either search may spend per episode (the random search needs it).
"""

from __future__ import annotations

import itertools
import math
import operator
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np

from contextrl.context.features import ContextBase, ContextError, context_type, feature
from contextrl.core.host import HostEnv
from contextrl.envs.rna.targets import (
    BASES,
    DATASETS,
    MAX_TARGETS,
    SyntheticTargets,
    Target,
    TargetError,
    TargetSets,
    fold,
    pair_table,
)

ACTION_PAIRS = ("AU", "CG", "GC", "UA", "GU", "UG")  # the first four start with BASES' A, C, G, U
"""Action k places ``ACTION_PAIRS[k]`` at an opening site and its pairing site, its first base alone
at an unpaired site (so actions 0–3 are A, C, G, U there). Only the first four are actions unless
``wobble_pairs=True``; then 4 and 5 add GU and UG (and repeat G and U at unpaired sites)."""
IMPROVEMENTS = ("exhaustive", "random")
"""Local improvement searches: LEARNA's exhaustive one (the default) or our seeded random search."""
MAX_EXHAUSTIVE_THRESHOLD = 9
"""The largest ``mutation_threshold`` the exhaustive search takes without a fold budget: distances up
to 8, so at most 4^8 = 65,536 folds in an episode (a threshold of 20 would allow 4^19)."""
MAX_EPOCHS = 64
"""Id ranges whose epoch the environment remembers; beyond that the oldest range's epoch restarts (a
range's order holds one id per target: contexts sampled over many ranges must not grow without end)."""
MAX_RADIUS = 32
WINDOW = 2 * MAX_RADIUS + 1
CHANNELS = ("unpaired", "opening", "closing", "outside")
"""One-hot channels of each observed site; a site beyond ``state_radius`` is all zeros."""


@context_type
class RnaDesignContext(ContextBase):
    """Context features of RnaDesign; the defaults are CARL's (Eterna100 in its ViennaRNA 2 version)."""

    mutation_threshold: float = feature(
        5.0,
        0.0,
        1000.0,
        unit="sites",
        doc="local improvement runs when the Hamming distance is below this (0 or 1: never)",
        affects=("reward",),
    )
    reward_exponent: float = feature(
        1.0, 0.1, 100.0, doc="reward is (1 - distance/length) to this power", affects=("reward",)
    )
    state_radius: int = feature(
        5,
        1,
        MAX_RADIUS,
        kind="int",
        unit="sites",
        doc="target sites seen on each side of the current site",
        affects=("observation",),
    )
    dataset: int = feature(
        "eterna100_v2",
        0,
        0,
        kind="categorical",
        choices=DATASETS,
        doc="where targets come from (synthetic: seeded Rfam-like stand-in for Rfam-Learn)",
        affects=("goal",),
    )
    target_id_first: int = feature(
        1, 1, MAX_TARGETS, kind="int", doc="first target id an episode may draw", affects=("goal",)
    )
    target_id_last: int = feature(
        0,
        0,
        MAX_TARGETS,
        kind="int",
        doc="last target id an episode may draw (0: the data set's last)",
        affects=("goal",),
    )


class RnaDesign(HostEnv):
    """RNA design (LEARNA): write a sequence that folds into a target structure (ViennaRNA).

    Observation: the target around the current site, ``2 × 32 + 1`` sites one-hot over
    ``CHANNELS`` (flattened), sites beyond ``state_radius`` all zeros, so every radius fits one space.
    Actions: ``Discrete(4)`` as LEARNA (``Discrete(6)`` with ``wobble_pairs``), see ``ACTION_PAIRS``.
    ``info`` always holds ``dataset`` and ``target_id``; the last step adds ``sequence`` (after the
    local improvement), ``structure`` (its fold), ``hamming_distance``, ``solved`` and ``folds`` (the
    vector env puts them in ``info["final_info"]``).

    ``data_dir``: a folder of data files named as the shipped ones (see ``targets``); ``synthetic``: a
    :class:`~contextrl.envs.rna.targets.SyntheticTargets` or a dict of its fields; ``improvement``:
    one of ``IMPROVEMENTS``; ``improvement_folds``: the local improvement's fold budget per episode
    (None: none, exhaustive search only); ``wobble_pairs``: GU and UG as actions 4 and 5.
    """

    context_type = RnaDesignContext
    default_max_steps = 451  # replaced per instance by the longest target it can draw

    def __init__(
        self,
        data_dir: str | Path | None = None,
        synthetic: SyntheticTargets | dict | None = None,
        improvement: str = "exhaustive",
        improvement_folds: int | None = None,
        wobble_pairs: bool = False,
        render_size: tuple[int, int] = (200, 640),
    ):
        if isinstance(synthetic, dict):
            synthetic = SyntheticTargets(**synthetic)
        if synthetic is not None and not isinstance(synthetic, SyntheticTargets):
            raise TypeError(f"synthetic must be a SyntheticTargets or a dict, got {synthetic!r}")
        if improvement not in IMPROVEMENTS:
            raise ValueError(
                f"improvement must be one of {list(IMPROVEMENTS)}, got {improvement!r}"
            )
        if improvement_folds is not None and (
            isinstance(improvement_folds, bool)
            or not isinstance(improvement_folds, (int, np.integer))
            or not 0 <= improvement_folds <= 100_000
        ):
            raise ValueError(
                "improvement_folds must be None (no budget) or an integer in [0, 100000], got "
                f"{improvement_folds!r}"
            )
        if improvement == "random" and improvement_folds is None:
            raise ValueError(
                "improvement='random' needs a fold budget: pass improvement_folds (e.g. 32); "
                "the random search has no end of its own"
            )
        if not isinstance(wobble_pairs, (bool, np.bool_)):
            raise ValueError(f"wobble_pairs must be True or False, got {wobble_pairs!r}")
        if len(render_size) != 2 or not all(
            isinstance(s, int) and 16 <= s <= 4096 for s in render_size
        ):
            raise ValueError(
                f"render_size must be (height, width) ints in [16, 4096], got {render_size!r}"
            )
        self.targets = TargetSets(data_dir, synthetic)
        self.improvement = improvement
        self.improvement_folds = None if improvement_folds is None else int(improvement_folds)
        self.wobble_pairs = bool(wobble_pairs)
        self.action_pairs = ACTION_PAIRS if wobble_pairs else ACTION_PAIRS[:4]
        self.render_size = tuple(render_size)
        self.default_max_steps = self.targets.max_length  # at most one action per site
        self.action_space = gymnasium.spaces.Discrete(len(self.action_pairs))
        self.base_observation_space = gymnasium.spaces.Box(
            0.0, 1.0, shape=(WINDOW * len(CHANNELS),), dtype=np.float32
        )
        self._offsets = np.arange(-MAX_RADIUS, MAX_RADIUS + 1)
        self.target: Target | None = None
        self._rng: np.random.Generator | None = None
        self._epochs: dict[tuple[str, int, int], tuple[np.ndarray, int]] = {}
        self._result: dict[str, Any] | None = None

    # ---- HostEnv interface -------------------------------------------------------------------------

    def target_range(self, values: dict[str, float]) -> tuple[str, int, int]:
        """(data set, first id, last id) of a checked context; ContextError naming an id out of range."""
        dataset = DATASETS[int(values["dataset"])]
        size = self.targets.size(dataset)
        first = int(values["target_id_first"])
        last = int(values["target_id_last"]) or size
        for name, target_id in (("target_id_first", first), ("target_id_last", last)):
            if target_id > size:
                raise ContextError(
                    f"{name}: target id {target_id} is out of range: data set {dataset} has "
                    f"ids 1..{size}"
                )
        if first > last:
            raise ContextError(
                f"target_id_first={first} comes after target_id_last={last}: the range of "
                f"{dataset} ids is empty"
            )
        return dataset, first, last

    def _check_threshold(self, values: dict[str, float]) -> None:
        """ContextError when the exhaustive search, without a fold budget, could not finish: a
        ``mutation_threshold`` above ``MAX_EXHAUSTIVE_THRESHOLD``."""
        threshold = values["mutation_threshold"]
        if (
            self.improvement == "exhaustive"
            and self.improvement_folds is None
            and threshold > MAX_EXHAUSTIVE_THRESHOLD
        ):
            raise ContextError(
                f"mutation_threshold={threshold:g} lets the exhaustive local improvement fold up to "
                f"4^{math.ceil(threshold) - 1} designs per episode; without a fold budget it takes "
                f"at most {MAX_EXHAUSTIVE_THRESHOLD} (4^{MAX_EXHAUSTIVE_THRESHOLD - 1} folds): lower "
                "it, or pass improvement_folds= (a budget) or improvement='random' to RnaDesign"
            )

    def reset_physics(self, context: Any, rng: np.random.Generator) -> np.ndarray:
        values = self.context_values(context)
        dataset, first, last = self.target_range(values)  # every check before anything changes
        self._check_threshold(values)
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"{self.name}: rng must be a numpy.random.Generator, got {rng!r}")
        if rng is not self._rng:  # reset(seed=...) made a new generator: new epochs from it
            self._epochs, self._rng = {}, rng
        self._begin(self.targets.get(dataset, self._next_id(dataset, first, last)), values)
        return self._observe()

    def _next_id(self, dataset: str, first: int, last: int) -> int:
        """The next id of the range's epoch (LEARNA: shuffled once per epoch, taken in order)."""
        key = (dataset, first, last)
        order, position = self._epochs.pop(key, (None, 0))  # popped: re-added as the newest
        if order is None or position == len(order):
            order, position = first + self._rng.permutation(last - first + 1), 0
        if len(self._epochs) >= MAX_EPOCHS:
            del self._epochs[next(iter(self._epochs))]  # the range used longest ago
        self._epochs[key] = (order, position + 1)
        return int(order[position])

    def _begin(self, target: Target, values: dict[str, float]) -> None:
        """Start designing ``target`` under checked context ``values``; precompute its observations'
        one-hot rows, padded with ``outside`` rows on both sides (one extra past the end)."""
        self.target = target
        self._threshold = values["mutation_threshold"]
        self._exponent = values["reward_exponent"]
        self._visible = (np.abs(self._offsets) <= int(values["state_radius"]))[:, None]
        partners, n = target.partners, len(target)
        sites = np.arange(n)
        self._decision_sites = np.flatnonzero((partners < 0) | (partners > sites))
        channel = np.where(partners < 0, 0, np.where(partners > sites, 1, 2))
        self._padded = np.zeros((n + WINDOW, len(CHANNELS)), np.float32)
        self._padded[:, 3] = 1.0
        self._padded[MAX_RADIUS + sites, 3] = 0.0
        self._padded[MAX_RADIUS + sites, channel] = 1.0
        self._target_bytes = np.frombuffer(target.structure.encode(), np.uint8)
        self._sequence = ["N"] * n
        self._step = 0
        self._result = None

    def step_physics(self, action) -> tuple[np.ndarray, float, bool]:
        if self.target is None or self._result is not None:
            raise RuntimeError(f"{self.name}: the episode is over (or never began); reset first")
        try:
            index = -1 if isinstance(action, (bool, np.bool_)) else operator.index(action)
        except TypeError:
            index = -1
        if not 0 <= index < len(self.action_pairs):
            raise ValueError(
                f"{self.name}: action must be an integer in [0, {len(self.action_pairs)}) "
                f"(wobble_pairs={self.wobble_pairs}), got {action!r}"
            )
        site = int(self._decision_sites[self._step])
        pair = self.action_pairs[index]
        self._sequence[site] = pair[0]
        partner = int(self.target.partners[site])
        if partner >= 0:
            self._sequence[partner] = pair[1]
        self._step += 1
        if self._step < len(self._decision_sites):
            return self._observe(), 0.0, False
        return self._observe(), self._finish(), True

    def step_info(self) -> dict[str, Any]:
        if self.target is None:
            return {}
        info = {"dataset": self.target.dataset, "target_id": self.target.id}
        if self._result is not None:
            info.update(self._result)
        return info

    # ---- design and reward ---------------------------------------------------------------------------
    def actions_for(self, sequence: str) -> list[int]:
        """The actions that write ``sequence`` for the current target (e.g. a known solution).

        ValueError when a pair of the target is not one the actions can place.
        """
        if self.target is None or len(sequence) != len(self.target):
            raise ValueError(
                f"{self.name}: reset first, then give a sequence of the target's length"
            )
        actions = []
        for site in self._decision_sites:
            partner = int(self.target.partners[site])
            if partner < 0:
                if sequence[site] not in BASES:
                    raise ValueError(f"{self.name}: {sequence[site]!r} is not a base of {BASES!r}")
                actions.append(BASES.index(sequence[site]))  # the pair starting with that base
                continue
            pair = sequence[site] + sequence[partner]
            if pair not in self.action_pairs:
                wobble = "" if self.wobble_pairs else " (wobble_pairs=True adds GU, UG)"
                raise ValueError(
                    f"{self.name}: sites {site + 1} and {partner + 1} pair in the target but the "
                    f"sequence puts {pair!r} there; placeable pairs are "
                    f"{list(self.action_pairs)}{wobble}"
                )
            actions.append(self.action_pairs.index(pair))
        return actions

    def _mismatches(self, structure: str) -> np.ndarray:
        """Sites where ``structure`` differs from the target (their count: the Hamming distance)."""
        return np.flatnonzero(np.frombuffer(structure.encode(), np.uint8) != self._target_bytes)

    def _finish(self) -> float:
        """Fold the finished design, improve it locally if it is close, and score it."""
        sequence = "".join(self._sequence)
        structure = fold(sequence)
        distance, folds = len(self._mismatches(structure)), 1
        if 0 < distance < self._threshold:  # strict, as LEARNA
            improve = self._exhaustive if self.improvement == "exhaustive" else self._random_search
            sequence, structure, distance, extra = improve(sequence, structure, distance)
            folds += extra
        self._result = {
            "sequence": sequence,
            "structure": structure,
            "hamming_distance": distance,
            "solved": distance == 0,
            "folds": folds,
        }
        return float((1.0 - distance / len(self.target)) ** self._exponent)

    def _exhaustive(
        self, sequence: str, structure: str, distance: int
    ) -> tuple[str, str, int, int]:
        """LEARNA's local improvement: fold every A/C/G/U combination at the mismatched sites (all
        but the design's own, already folded), keep the first of smallest distance, stop at 0 or
        when ``improvement_folds`` (if set) are spent. (sequence, structure, distance, folds)."""
        sites = self._mismatches(structure)
        design = np.array(list(sequence))
        best, folds = (sequence, structure, distance), 0
        for bases in itertools.product(BASES, repeat=len(sites)):
            if best[2] == 0 or folds == self.improvement_folds:
                break
            candidate = design.copy()
            candidate[sites] = bases
            candidate_sequence = "".join(candidate)
            if candidate_sequence == sequence:
                continue
            candidate_structure = fold(candidate_sequence)
            folds += 1
            candidate_distance = len(self._mismatches(candidate_structure))
            if candidate_distance < best[2]:
                best = (candidate_sequence, candidate_structure, candidate_distance)
        return (*best, folds)

    def _random_search(
        self, sequence: str, structure: str, distance: int
    ) -> tuple[str, str, int, int]:
        """Our seeded local search over the mismatched sites (a mismatched paired site gets a new
        placeable pair), each mutation kept when it does not increase d, within
        ``improvement_folds`` folds, stopping once d = 0."""
        best, partners = list(sequence), self.target.partners
        folds = 0
        while folds < self.improvement_folds and distance > 0:
            wrong = self._mismatches(structure)
            site = int(wrong[self._rng.integers(len(wrong))])
            candidate = best.copy()
            partner = int(partners[site])
            if partner >= 0:
                opening, closing = min(site, partner), max(site, partner)
                current = candidate[opening] + candidate[closing]
                pairs = [p for p in self.action_pairs if p != current]
                candidate[opening], candidate[closing] = pairs[self._rng.integers(len(pairs))]
            else:
                bases = [b for b in BASES if b != candidate[site]]
                candidate[site] = bases[self._rng.integers(len(bases))]
            candidate_structure = fold("".join(candidate))
            folds += 1
            candidate_distance = len(self._mismatches(candidate_structure))
            if candidate_distance <= distance:  # ties kept: the search drifts across plateaus
                best, structure, distance = candidate, candidate_structure, candidate_distance
        return "".join(best), structure, distance, folds

    # ---- observation and rendering -------------------------------------------------------------------
    def _observe(self) -> np.ndarray:
        """The target around the current site (one past the end once the design is complete)."""
        n_sites = len(self._decision_sites)
        centre = int(self._decision_sites[self._step]) if self._step < n_sites else len(self.target)
        return (self._padded[centre : centre + WINDOW] * self._visible).ravel()

    def render_text(self) -> str:
        """Target, the sequence so far (N: not yet placed) and, once folded, the design's structure."""
        if self.target is None:
            return ""
        lines = [self.target.structure, "".join(self._sequence)]
        if self._result is not None:
            lines.append(self._result["structure"])
        return "\n".join(lines)

    def render_frame(self) -> np.ndarray:
        """An arc diagram: bases as coloured dots, target pairs above, the folded design's below."""
        from contextrl.render.canvas import Canvas

        height, width = self.render_size
        n = len(self.target) if self.target is not None else 1
        half_height = (n + 1.0) * height / width / 2  # one world unit per site on both axes
        canvas = Canvas((0.0, n + 1.0, -half_height, half_height), width=width, height=height)
        if self.target is None:
            return canvas.frame()
        colours = {"A": (0, 160, 0), "C": (0, 80, 220), "G": (230, 160, 0), "U": (220, 0, 0)}
        target_pairs = _pairs(self.target.partners)
        folded = self._result["structure"] if self._result is not None else None
        for pairs, side, colour in (
            (target_pairs, 1.0, (90, 90, 90)),
            (_pairs(pair_table(folded, "folded design")) if folded else [], -1.0, (140, 0, 160)),
        ):
            for opening, closing in pairs:
                reach = side * 0.95 * half_height * (closing - opening) / n
                _arc(canvas, opening + 1, closing + 1, reach, colour)
        if self._step < len(self._decision_sites):
            site = int(self._decision_sites[self._step]) + 1
            canvas.line((site, -half_height), (site, half_height), 0.5, (255, 200, 200))
        for site, base in enumerate(self._sequence):
            canvas.circle((site + 1, 0.0), 0.45, colours.get(base, (200, 200, 200)))
        return canvas.frame()


def _pairs(partners: np.ndarray) -> list[tuple[int, int]]:
    return [(i, int(j)) for i, j in enumerate(partners) if j > i]


def _arc(canvas, start: float, end: float, height: float, colour) -> None:
    """Half an ellipse from ``start`` to ``end`` reaching ``height`` (negative: below the line)."""
    angles = np.linspace(0.0, np.pi, 13)
    xs = (start + end) / 2 - np.cos(angles) * (end - start) / 2
    ys = np.sin(angles) * height
    points = np.stack([xs, ys], axis=1)
    for start_point, end_point in zip(points[:-1], points[1:], strict=True):
        canvas.line(tuple(start_point), tuple(end_point), 0.0, colour)  # thinnest line


__all__ = [
    "ACTION_PAIRS",
    "CHANNELS",
    "IMPROVEMENTS",
    "RnaDesign",
    "RnaDesignContext",
    "TargetError",
]
