"""Coverage of the library's intervals, measured on synthetic experiments whose truth is known.

An experiment draws two agents' score matrices (seeds × contexts) from the same distribution, so
every comparison has a known true value (a difference of 0, a probability of improvement of ½). A
score is ``context effect + seed effect + noise``: in the ``shared`` design each seed's effect is one
draw shared by all its contexts (one agent tested on many contexts); in the ``independent`` design
every (context, seed) cell is its own run with its own effect (a specialist per context). Contexts are
drawn afresh in every experiment and are the same for both agents, as in a protocol that tests every
agent on one sampled test set.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from contextrl.analysis import intervals, metrics


@dataclasses.dataclass(frozen=True)
class Synthetic:
    """The sizes and spreads of a synthetic experiment."""

    seeds: int = 10
    contexts: int = 50
    seed_sd: float = 20.0
    context_sd: float = 50.0
    noise_sd: float = 10.0

    def draw(self, rng: np.random.Generator, designs: tuple[str, str]) -> list[np.ndarray]:
        """Two score matrices with the same distribution, one per design (``shared`` or
        ``independent``), on the same contexts."""
        context = rng.normal(0.0, self.context_sd, size=(1, self.contexts))
        shape = (self.seeds, self.contexts)
        out = []
        for design in designs:
            if design == "shared":
                seed = rng.normal(0.0, self.seed_sd, size=(self.seeds, 1))
            else:
                seed = rng.normal(0.0, self.seed_sd, size=shape)
            out.append(context + seed + rng.normal(0.0, self.noise_sd, size=shape))
        return out


# A statistic of two samples and its true value when both come from the same distribution.
STATISTICS: dict[str, tuple[Callable, float]] = {
    "difference of means": (metrics.difference_of_means, 0.0),
    "optimality gap": (lambda x, y: metrics.context_optimality_gap(x, y), 0.0),
    "probability of improvement": (metrics.probability_of_improvement, 0.5),
}
UNIT_OF = {"shared": intervals.SEEDS, "independent": intervals.RUNS}
# Every statistic in both designs, and the optimality gap's own (a shared general agent against
# independent specialists): the cases whose coverage the tests and the benchmark measure.
CASES = [
    ("difference of means", ("shared", "shared")),
    ("probability of improvement", ("shared", "shared")),
    ("optimality gap", ("shared", "independent")),
    ("difference of means", ("independent", "independent")),
    ("probability of improvement", ("independent", "independent")),
    ("optimality gap", ("independent", "independent")),
]


def coverage(
    statistic: str,
    designs: tuple[str, str],
    *,
    experiments: int = 1000,
    synthetic: Synthetic = Synthetic(),
    contexts: str = intervals.SAMPLED,
    reps: int = 1000,
    seed: int = 0,
    interval: Callable | None = None,
) -> float:
    """The fraction of ``experiments`` whose 95 % interval of ``statistic`` covers its true value.

    The intervals are :func:`intervals.two_sample_ci` with the units the designs call for, unless
    ``interval(x, y, metric, seed)`` is given (another method to measure on the same experiments)."""
    metric, truth = STATISTICS[statistic]
    units = tuple(UNIT_OF[d] for d in designs)
    rng = np.random.default_rng(seed)
    covered = 0
    for experiment in range(experiments):
        x, y = synthetic.draw(rng, designs)
        if interval is None:
            found = intervals.two_sample_ci(
                x, y, metric, units=units, contexts=contexts, reps=reps, seed=experiment
            )
        else:
            found = interval(x, y, metric, experiment)
        covered += found.low <= truth <= found.high
    return covered / experiments
