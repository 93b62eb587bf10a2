"""Measure the learning tests' statistics over many seeds, to set thresholds that luck cannot cross.

Run each numerics in its own process (XLA reads its flags once, when JAX starts):

    python -m tests.helpers.margins --seeds 16                # XLA's default numerics
    XLA_FLAGS=--xla_cpu_enable_fast_math=true python -m tests.helpers.margins --seeds 16

Stable-Baselines3's run does not go through XLA; its second numerics is torch without SIMD kernels
(``ATEN_CPU_CAPABILITY=default``). The host-path RNA run compiles its networks inside the library, so
it is also measured as the suite compiles it (``XLA_FLAGS="--xla_cpu_use_fusion_emitters=false
--xla_backend_optimization_level=0"``, tests/conftest.py); the JAX cases pin XLA's default numerics
whatever the flags (``learning.MEASURED_NUMERICS``; UR5e's the older emitters, ``OLDER_EMITTERS``).

It prints, per case and statistic, the per-seed values sorted and in seed order, their minimum, median
and maximum; the tests' docstrings quote these figures. ``--first`` moves the seed range (seeds first
.. first+n-1).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from contextrl.xla_flags import xla_cpu_workaround  # noqa: E402

xla_cpu_workaround()  # as the test session does, before JAX starts

from tests.helpers import learning  # noqa: E402


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="*", default=list(learning.CASES), help="default: all")
    parser.add_argument("--seeds", type=int, default=16)
    parser.add_argument("--first", type=int, default=0)
    args = parser.parse_args(argv)
    unknown = sorted(set(args.cases) - set(learning.CASES))
    if unknown:
        parser.error(f"unknown cases {unknown}; choose from {sorted(learning.CASES)}")
    seeds = np.arange(args.first, args.first + args.seeds)
    print(f"XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}; seeds {seeds[0]}..{seeds[-1]}")
    for name in args.cases:
        start = time.perf_counter()
        statistics = learning.CASES[name](seeds)
        print(f"\n{name} ({time.perf_counter() - start:.0f} s)")
        for stat, values in statistics.items():
            values = np.asarray(values, float)
            print(
                f"  {stat}: min {values.min():.4g}  median {np.median(values):.4g}  "
                f"max {values.max():.4g}  sorted {np.round(np.sort(values), 3).tolist()}  "
                f"by seed {np.round(values, 3).tolist()}"
            )
        sys.stdout.flush()


if __name__ == "__main__":
    main()
