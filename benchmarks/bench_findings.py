"""The paper's findings at the budgets they are calibrated at, each with its 95 % interval and every
seed's return. Run it after any change to agents, context selectors or protocols: a faster agent that no
longer shows a finding is a regression, and so is a finding that appears from nowhere.

    python benchmarks/bench_findings.py                              # every finding, seed sets 0, 1, 2
    python benchmarks/bench_findings.py --only optimality_gap_ppo --seed-sets 0
    python benchmarks/bench_findings.py --out runs/findings          # resumes runs already there

Each finding is an example spec run unchanged except for its base seed (``--seed``: the contexts, the
training keys and the bootstrap), on the processes executor, into OUT/<finding>-s<seed>; a finished run
is read back, not retrained. The statistic is the one the run's report states (the same function).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

from contextrl.analysis.scores import gap_statistics
from contextrl.experiments import RunDir, expand, resume, run_experiment
from contextrl.experiments.reports import run_cells
from contextrl.experiments.spec import load_yaml

ROOT = Path(__file__).resolve().parents[1]


def optimality_gap(run: RunDir) -> list[tuple[str, str]]:
    """The gap E_c[G_specialist − G_general] with its interval, whether the interval excludes zero,
    and each seed's mean return over its contexts."""
    spec = run.spec()
    rows = []
    for variant, stats in gap_statistics(
        run_cells(run, expand(spec), run.results()), spec.variants, **spec.design
    ).items():
        excludes = "yes" if stats.gap.low > 0 or stats.gap.high < 0 else "no"
        seeds = stats.per_seed()
        rows += [
            (f"gap ({variant}) [95% CI]", str(stats.gap)),
            ("interval excludes 0", excludes),
            ("P(specialist > general)", str(stats.improvement)),
            ("general, per seed", " ".join(f"{v:.0f}" for v in seeds["general"])),
            ("specialists, per seed", " ".join(f"{v:.0f}" for v in seeds["specialists"])),
        ]
    return rows


@dataclasses.dataclass(frozen=True)
class Finding:
    spec: str  # an example spec, relative to the repository
    claim: str  # the paper's claim in one line
    statistic: Callable[[RunDir], list[tuple[str, str]]]


FINDINGS = {
    "optimality_gap_ppo": Finding(
        "examples/optimality_gap_cartpole.yaml",
        "§6.2: specialists beat the general agent (paper: gap ≥ 30 on CartPole)",
        optimality_gap,
    ),
    "optimality_gap_c51": Finding(
        "examples/optimality_gap_cartpole_c51.yaml",
        "§6.2 with the paper's C51, at a reduced budget (8 contexts, 3 seeds, 30,000 steps)",
        optimality_gap,
    ),
}


def run_finding(name: str, seed: int, out: Path, executor: str) -> tuple[RunDir, float]:
    """Train the finding's spec with base seed ``seed`` (or finish it, if its run folder exists)."""
    path = out / f"{name}-s{seed}"
    start = time.perf_counter()
    if path.exists():
        run, _ = resume(path, executor=executor)
    else:
        spec_path = ROOT / FINDINGS[name].spec
        spec = load_yaml(spec_path.read_text(), str(spec_path)) | {"seed": seed}
        run, _ = run_experiment(spec, out=path, executor=executor)
    return run, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", nargs="+", choices=sorted(FINDINGS), default=sorted(FINDINGS))
    parser.add_argument("--seed-sets", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--out", type=Path, default=Path("runs/findings"))
    parser.add_argument("--executor", default="processes", choices=["processes", "local"])
    args = parser.parse_args()
    table = []
    for name in args.only:
        for seed in args.seed_sets:
            run, seconds = run_finding(name, seed, args.out, args.executor)
            rows = FINDINGS[name].statistic(run)
            chunks = sum(run.timings().values())
            table.append(
                (name, seed, f"{chunks / 60:.1f} min of training, summed over chunks", rows)
            )
            print(f"done: {name} seed {seed}, {seconds / 60:.1f} min in this call", flush=True)
    for name in args.only:
        print(f"\n{name}: {FINDINGS[name].claim}  ({FINDINGS[name].spec})")
        for finding, seed, wall, rows in table:
            if finding != name:
                continue
            print(f"  seed set {seed} ({wall}):")
            width = max(len(label) for label, _ in rows)
            for label, value in rows:
                print(f"    {label:<{width}}  {value}")
    gaps = [v for *_, rows in table for label, v in rows if label == "interval excludes 0"]
    print(f"\n{gaps.count('yes')} of {len(gaps)} gap intervals exclude zero")


if __name__ == "__main__":
    main()
