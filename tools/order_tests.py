"""Write the order in which the two workers of `make test` and `make test-slow` take the test files.

    python tools/order_tests.py .pytest_cache/junit.xml --slow .pytest_cache/junit-slow.xml

Each file's seconds are the sum of its tests' times (setup, call and teardown: a module fixture's
compile time counts) in pytest's JUnit report. Take the reports of a fresh clone's `make test` and
then `make test-slow`, as CI runs them: a later run loads most programs from the suite's compilation
cache (.pytest_cache/jax), so its durations understate CI's. Each tier is ordered on its own, its
files handed out longest first, so that the short ones fill in at the end and both workers finish
together. Two files that each start PB2 on a local Ray (APART) must not run at the same time: the
order is simulated on two workers, and while their runs overlap the later one moves one place down. The result, `tests/file_durations.json`, is what
tests/conftest.py reads and what tests/repository/test_suite_budget.py holds to the tiers' budgets.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUTPUT = ROOT / "tests" / "file_durations.json"
WORKERS = 2
APART = ("experiments/test_hpo.py", "experiments/test_matrix.py")


def file_seconds(junit: Path) -> dict[str, float]:
    """Seconds per test file (relative to tests/), from a JUnit report's test cases."""
    seconds: dict[str, float] = defaultdict(float)
    for case in ET.parse(junit).getroot().iter("testcase"):
        seconds[test_file(case.get("classname", ""))] += float(case.get("time", 0.0))
    return dict(seconds)


def test_file(classname: str) -> str:
    """tests.envs.brax.test_brax.TestX -> envs/brax/test_brax.py (the longest prefix that is a file)."""
    parts = classname.split(".")
    for end in range(len(parts), 1, -1):
        candidate = Path(*parts[:end]).with_suffix(".py")
        if (ROOT / candidate).is_file():
            return candidate.relative_to("tests").as_posix()
    raise ValueError(f"test case class {classname!r}: no file under tests/ matches it")


def schedule(order: list[str], seconds: dict[str, float]) -> dict[str, tuple[float, float]]:
    """When each file starts and ends if WORKERS workers take the files in this order."""
    free = [0.0] * WORKERS
    spans = {}
    for name in order:
        worker = free.index(min(free))
        spans[name] = (free[worker], free[worker] + seconds[name])
        free[worker] = spans[name][1]
    return spans


def ordered(seconds: dict[str, float]) -> list[str]:
    """Longest first, with the APART files moved until their runs do not overlap."""
    order = sorted(seconds, key=lambda name: (-seconds[name], name))
    first, second = (
        (name for name in order if name in APART)
        if all(n in seconds for n in APART)
        else (None, None)
    )
    while first is not None:
        spans = schedule(order, seconds)
        if spans[second][0] >= spans[first][1] or spans[first][0] >= spans[second][1]:
            break
        later = max(first, second, key=order.index)
        at = order.index(later)
        if at == len(order) - 1:
            sys.exit(f"cannot keep {' and '.join(APART)} apart with these durations")
        order[at], order[at + 1] = order[at + 1], order[at]
    return order


def tier(junit: Path) -> tuple[list[str], dict[str, float], int]:
    """A tier's files in their order, their seconds, and its expected seconds on WORKERS workers."""
    seconds = file_seconds(junit)
    order = ordered(seconds)
    spans = schedule(order, seconds)
    return order, seconds, round(max(end for _, end in spans.values()))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "junit", type=Path, help="pytest's --junitxml report of a whole `make test`"
    )
    parser.add_argument("--slow", type=Path, required=True, help="the report of `make test-slow`")
    args = parser.parse_args(argv)
    for flag, path in (("junit", args.junit), ("--slow", args.slow)):
        if not path.is_file():
            parser.error(
                f"{flag}: {path} is not a file; run `make test` and `make test-slow` first"
            )
    order, seconds, expected = tier(args.junit)
    slow_order, slow_seconds, slow_expected = tier(args.slow)
    record = {
        "measured": datetime.date.today().isoformat(),
        "cores": os.cpu_count(),
        "workers": WORKERS,
        "expected_seconds": expected,
        "expected_slow_seconds": slow_expected,
        "files": {name: round(seconds[name], 1) for name in order},
        "slow_files": {name: round(slow_seconds[name], 1) for name in slow_order},
    }
    OUTPUT.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    print(
        f"{OUTPUT.relative_to(ROOT)}: {len(order)} files, about {expected} s on {WORKERS} workers; "
        f"slow tier {len(slow_order)} files, about {slow_expected} s"
    )


if __name__ == "__main__":
    main()
