"""Seeded bootstrap confidence intervals that resample what was replicated independently.

Which unit is independent depends on the experiment's design, so every interval names it:

- ``SEEDS``: one agent per seed tested on every context (a general agent, a sensitivity sweep, a
  visibility variant). Its returns across contexts share its training, so a replicate resamples whole
  rows: seeds, with all their contexts together.
- ``RUNS``: an independent run per context and seed (the specialists of the optimality gap, rliable's
  Atari setting). A replicate resamples each context's runs on their own: rliable's stratified
  bootstrap (Agarwal et al., 2021), which is right only when runs on different tasks are independent.

Where the test contexts are themselves a sample from a distribution and the claim is about that
distribution (``contexts=SAMPLED``), a replicate also resamples contexts, the same ones for every
sample (they were tested on the same contexts). Seeds are crossed with contexts, so a ``SEEDS``
sample resamples both (the two-way bootstrap, slightly conservative: Owen, 2007); runs are nested in
their context, so a ``RUNS`` sample resamples contexts only, each with all its runs (resampling the
runs too would count their spread twice: Ren et al., 2010). Claims about a fixed set of contexts (a
grid, a sweep of magnitudes) resample seeds or each context's runs only.

A percentile interval from few seeds is too narrow (the bootstrap's spread is that of a sample of n,
without the n − 1 correction, and its tails are normal's, not Student's). The interval is widened as
Hesterberg's expanded percentile interval (The American Statistician, 2015): the tail probability
α/2 becomes Φ(−√(n/(n−1)) · t_{α/2, df}), with n and df from the design. Its coverage is measured by
simulation against known truth in the tests. Every draw comes from ``numpy.random.default_rng(seed)``.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from contextrl.analysis.metrics import as_scores

SEEDS = "seeds"  # one agent per seed, tested on every context: seeds resampled whole
RUNS = "runs"  # a run of its own per context and seed: each context's runs resampled alone
UNITS = (SEEDS, RUNS)
FIXED = "fixed"  # the claim is about the contexts tested
SAMPLED = "sampled"  # the contexts are a sample from the distribution the claim is about
CONTEXTS = (FIXED, SAMPLED)
_CELLS_PER_CHUNK = 8_000_000  # replicates are evaluated in chunks of about this many cells


@dataclasses.dataclass(frozen=True)
class Interval:
    """A point estimate and its percentile confidence interval."""

    point: float
    low: float
    high: float

    def as_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)

    def __str__(self) -> str:
        return f"{self.point:.4g} [{self.low:.4g}, {self.high:.4g}]"


def _check(reps: int, confidence: float, units: Sequence[str], contexts: str) -> None:
    if isinstance(reps, bool) or not isinstance(reps, (int, np.integer)) or reps < 1:
        raise ValueError(f"reps must be a positive integer, got {reps!r}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")
    for unit in units:
        if unit not in UNITS:
            raise ValueError(f"unit: unknown unit {unit!r}; choose one of {list(UNITS)}")
    if contexts not in CONTEXTS:
        raise ValueError(f"contexts: unknown design {contexts!r}; choose one of {list(CONTEXTS)}")


def _present_runs(scores: np.ndarray) -> np.ndarray:
    """Per context, how many runs have a return."""
    return (~np.ma.getmaskarray(scores)).sum(axis=0)


def replication(
    samples: Sequence[np.ndarray], units: Sequence[str], contexts: str
) -> tuple[int, int]:
    """The design's n and degrees of freedom, for the interval's small-sample widening.

    Seeds are the units wherever a sample has them (few, and shared by all their contexts): n is
    the fewest seeds of a ``SEEDS`` sample (each sample's spread is that of its own seeds) and each
    sample adds its seeds − 1 degrees of freedom (one sample: Hesterberg's n and n − 1; two: the
    two-sample t's pooled count). Without seeds, sampled contexts are the units (resampled
    together: n contexts, n − 1), and with fixed contexts each context's runs are (n the fewest
    runs of a context, Σ (runs − 1)).
    """
    pairs = list(zip(samples, units, strict=True))
    seeds = [int((~np.ma.getmaskarray(s)).any(axis=1).sum()) for s, u in pairs if u == SEEDS]
    if seeds:
        return min(seeds), sum(k - 1 for k in seeds)
    runs = [_present_runs(s) for s, u in pairs if u == RUNS]
    if contexts == SAMPLED:
        width = int(min((r > 0).sum() for r in runs))
        return width, width - 1
    fewest = min(int(r[r > 0].min()) for r in runs)
    return fewest, int(sum(np.maximum(r - 1, 0).sum() for r in runs))


def tail_probability(confidence: float, n: int, df: int) -> float:
    """The percentile at each end of Hesterberg's expanded percentile interval (α/2 where n < 2
    or df < 1: there is no spread to widen)."""
    import scipy.stats  # a second to import: only a bootstrap needs it

    alpha = 1.0 - confidence
    if n < 2 or df < 1:
        return alpha / 2.0
    widened = np.sqrt(n / (n - 1.0)) * scipy.stats.t.ppf(1.0 - alpha / 2.0, df)
    return float(scipy.stats.norm.sf(widened))


def _resample(
    scores: np.ndarray,
    unit: str,
    size: int,
    columns: np.ndarray | None,
    rng: np.random.Generator,
) -> np.ndarray:
    """``size`` replicates (replicates × runs × contexts) of one sample: its contexts taken as
    ``columns`` (replicates × contexts; None: as they are), then its seeds drawn with replacement,
    or, where the contexts were not resampled, each context's runs."""
    resampled = columns is not None
    if columns is None:
        columns = np.broadcast_to(np.arange(scores.shape[1]), (size, scores.shape[1]))
    masked = np.ma.is_masked(scores)
    data = np.ma.getdata(scores)[:, columns].transpose(1, 0, 2)
    mask = np.ma.getmaskarray(scores)[:, columns].transpose(1, 0, 2) if masked else None
    runs = data.shape[1]
    if unit == RUNS and resampled:  # runs nested in resampled contexts come with them
        pass
    elif unit == SEEDS:  # whole rows: a seed keeps all its contexts (and its missing cells)
        rows = rng.integers(0, runs, size=data.shape[:2])
        data = data[np.arange(len(rows))[:, None], rows]
        mask = mask[np.arange(len(rows))[:, None], rows] if masked else None
    elif not masked:  # each context's runs on their own
        rows = rng.integers(0, runs, size=data.shape)
        data = np.take_along_axis(data, rows, 1)
    else:  # a context draws as many runs as it has, from those it has; the rest stays masked
        counts = (~mask).sum(axis=1, keepdims=True)
        present_first = np.argsort(mask, axis=1, kind="stable")
        draws = rng.integers(0, np.maximum(counts, 1), size=data.shape)
        data = np.take_along_axis(data, np.take_along_axis(present_first, draws, 1), 1)
        mask = np.arange(runs)[None, :, None] >= counts
    return np.ma.MaskedArray(data, mask) if masked and mask.any() else data


def _bootstrap(
    samples: Sequence,
    metric: Callable[..., float],
    units: Sequence[str],
    contexts: str,
    *,
    reps: int,
    confidence: float,
    seed: int,
) -> Interval:
    """The one interval every statistic is given: ``metric(*samples)`` with its bootstrap
    distribution under the design (``units`` per sample, ``contexts``), expanded for few seeds.

    ``metric`` must take stacks of matrices (a leading replicate axis) and return one value per
    replicate, as every function of :mod:`contextrl.analysis.metrics` does."""
    _check(reps, confidence, units, contexts)
    names = ["scores"] if len(samples) == 1 else [f"scores_{c}" for c in "xyzw"[: len(samples)]]
    samples = [as_scores(s, name) for s, name in zip(samples, names, strict=True)]
    if len(samples) != len(units):
        raise ValueError(f"{len(samples)} score matrices but {len(units)} units")
    width = samples[0].shape[1]
    if contexts == SAMPLED and any(s.shape[1] != width for s in samples):
        raise ValueError("contexts are resampled together, so every matrix needs the same contexts")
    rng = np.random.default_rng(seed)
    cells = sum(s.size for s in samples) * max(s.shape[0] for s in samples)
    chunk = max(1, min(reps, _CELLS_PER_CHUNK // cells))
    values = []
    for start in range(0, reps, chunk):
        size = min(chunk, reps - start)
        columns = rng.integers(0, width, size=(size, width)) if contexts == SAMPLED else None
        replicates = [
            _resample(s, unit, size, columns, rng) for s, unit in zip(samples, units, strict=True)
        ]
        values.append(np.atleast_1d(np.asarray(metric(*replicates), dtype=np.float64)))
    values = np.concatenate(values)
    if values.shape != (reps,):
        raise ValueError(
            f"the metric gave {values.size} values for {reps} replicates; it must take a stack "
            "of matrices (a leading replicate axis) and give one value per matrix"
        )
    tail = 100.0 * tail_probability(confidence, *replication(samples, units, contexts))
    low, high = np.nanpercentile(values, [tail, 100.0 - tail])
    return Interval(float(metric(*samples)), float(low), float(high))


def bootstrap_ci(
    scores,
    metric: Callable[[np.ndarray], float],
    *,
    unit: str = SEEDS,
    contexts: str = FIXED,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> Interval:
    """``metric`` on one score matrix (runs × contexts) with its interval under the design."""
    return _bootstrap(
        [scores], metric, [unit], contexts, reps=reps, confidence=confidence, seed=seed
    )


def two_sample_ci(
    scores_x,
    scores_y,
    metric: Callable[[np.ndarray, np.ndarray], float],
    *,
    units: tuple[str, str] = (SEEDS, SEEDS),
    contexts: str = FIXED,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> Interval:
    """A two-sample metric (difference of means, gap, probability of improvement): the samples'
    seeds or runs resampled independently (they were trained apart), their contexts together."""
    return _bootstrap(
        [scores_x, scores_y], metric, units, contexts, reps=reps, confidence=confidence, seed=seed
    )


def interval_estimates(
    scores_by_name: Mapping[str, np.ndarray],
    metrics: Mapping[str, Callable[[np.ndarray], float]],
    *,
    units: Mapping[str, str] | None = None,
    contexts: str = FIXED,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> dict[str, dict[str, Interval]]:
    """Every metric for every named score matrix: ``{name: {metric: Interval}}``; ``units`` says
    each matrix's unit (default ``SEEDS``).

    Each (matrix, metric) pair gets its own generator derived from ``seed``, the metric's name and the
    scores themselves (values and missing cells), not from names or positions: the same statistic of
    the same scores has the same interval in every table of a report, and adding a metric or an agent
    never changes the intervals of the others.
    """
    out: dict[str, dict[str, Interval]] = {}
    for name, scores in scores_by_name.items():
        checked = as_scores(scores, str(name))
        fingerprint = hashlib.blake2b(repr(checked.shape).encode(), digest_size=8)
        fingerprint.update(np.ma.getdata(checked).tobytes())
        fingerprint.update(np.ma.getmaskarray(checked).tobytes())
        out[name] = {}
        for metric_name, metric in metrics.items():
            stream = hashlib.blake2b(metric_name.encode(), digest_size=8, key=fingerprint.digest())
            entropy = [seed, *np.frombuffer(stream.digest(), dtype=np.uint32).tolist()]
            sub_seed = int(np.random.SeedSequence(entropy).generate_state(1)[0])
            out[name][metric_name] = bootstrap_ci(
                checked,
                metric,
                unit=(units or {}).get(name, SEEDS),
                contexts=contexts,
                reps=reps,
                confidence=confidence,
                seed=sub_seed,
            )
    return out


def curve_band(
    curves, *, reps: int = 1000, confidence: float = 0.95, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and bootstrap band of training curves shaped (seeds × points), resampling seeds, with
    the same small-sample widening as every interval."""
    curves = as_scores(curves, "curves")
    _check(reps, confidence, (), FIXED)
    rng = np.random.default_rng(seed)
    runs = curves.shape[0]
    rows = rng.integers(0, runs, size=(reps, runs))
    # a point no resampled run reaches has no mean in that replicate (masked cells: missing runs)
    means = np.ma.filled(curves[rows].mean(axis=1), np.nan)
    tail = 100.0 * tail_probability(confidence, runs, runs - 1)
    low, high = np.nanpercentile(means, [tail, 100.0 - tail], axis=0)
    return np.ma.filled(curves.mean(axis=0), np.nan), low, high
