"""Coverage of the 95 % intervals on synthetic experiments whose truth is known, for the library's
design-aware bootstrap and for rliable's stratified percentile bootstrap, on the same experiments.

    python benchmarks/interval_coverage.py                      # 1,000 experiments, 10 seeds × 50 contexts
    python benchmarks/interval_coverage.py --experiments 200 --contexts 20

Two agents of one distribution (a true difference of 0, a probability of improvement of ½):
``shared`` draws one effect per seed for all its contexts (one agent tested on many contexts),
``independent`` one per cell (a run per context and seed). A coverage near 0.95 is calibrated.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from contextrl.analysis import calibration, intervals


def stratified_percentile(reps: int):
    """rliable's interval: every context's runs resampled on their own, plain 2.5/97.5 percentiles."""

    def interval(x, y, metric, seed):
        rng = np.random.default_rng(seed)
        xs, ys = (intervals._resample(m, intervals.RUNS, reps, None, rng) for m in (x, y))
        low, high = np.percentile(metric(xs, ys), [2.5, 97.5])
        return intervals.Interval(float(metric(x, y)), float(low), float(high))

    return interval


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiments", type=int, default=1000)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--contexts", type=int, default=50)
    parser.add_argument("--reps", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    synthetic = calibration.Synthetic(seeds=args.seeds, contexts=args.contexts)
    print(
        f"{args.experiments} experiments of {args.seeds} seeds × {args.contexts} contexts, "
        f"{args.reps} replicates; load average {os.getloadavg()[0]:.2f}"
    )
    print(f"{'statistic':28} {'designs':26} {'design-aware':>13} {'stratified':>11} {'seconds':>8}")
    for statistic, designs in calibration.CASES:
        start = time.perf_counter()
        common = {"experiments": args.experiments, "synthetic": synthetic, "seed": args.seed}
        ours = calibration.coverage(statistic, designs, reps=args.reps, **common)
        before = calibration.coverage(
            statistic, designs, interval=stratified_percentile(args.reps), **common
        )
        print(
            f"{statistic:28} {' × '.join(designs):26} {ours:13.3f} {before:11.3f} "
            f"{time.perf_counter() - start:8.0f}"
        )


if __name__ == "__main__":
    main()
