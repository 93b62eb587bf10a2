"""The suite keeps its budget: by the durations measured in a fresh clone's run
(tests/file_durations.json, written by `make test-order`), `make test` fits 15 minutes on its two
workers and both tiers 40 (CI's 50 minutes with installing, the docs and the main job); the measured
files exist in the tier they were measured in; and a file that takes over a minute outside the slow
tier without having been measured fails the run that shows it."""

import importlib.util
import json
import types

import pytest

from tests.conftest import UNMEASURED_FILE_LIMIT_S, FileCosts
from tests.helpers import ROOT

pytestmark = pytest.mark.quick

_spec = importlib.util.spec_from_file_location("order_tests", ROOT / "tools" / "order_tests.py")
order_tests = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(order_tests)

DURATIONS = json.loads((ROOT / "tests" / "file_durations.json").read_text(encoding="utf-8"))
MAKE_TEST_BUDGET_S = 15 * 60
BOTH_TIERS_BUDGET_S = 40 * 60


def expected_seconds(files: dict[str, float]) -> float:
    """When the last of two workers finishes, taking the files in the recorded order."""
    return max(end for _, end in order_tests.schedule(list(files), files).values())


def test_make_test_fits_fifteen_minutes_and_both_tiers_forty_by_their_measured_durations():
    assert DURATIONS["workers"] == order_tests.WORKERS == 2
    expected = expected_seconds(DURATIONS["files"])
    assert expected == pytest.approx(DURATIONS["expected_seconds"], abs=1)
    assert expected <= MAKE_TEST_BUDGET_S, (
        f"make test needs about {expected:.0f} s on two workers, over its {MAKE_TEST_BUDGET_S} s: "
        "mark what cannot be made cheap slow"
    )
    slow = expected_seconds(DURATIONS["slow_files"])
    assert slow == pytest.approx(DURATIONS["expected_slow_seconds"], abs=1)
    assert expected + slow <= BOTH_TIERS_BUDGET_S, (
        f"make test and make test-slow need about {expected + slow:.0f} s, over {BOTH_TIERS_BUDGET_S} s"
    )


def test_every_measured_file_exists_in_the_tier_it_was_measured_in():
    for name in DURATIONS["files"]:
        assert (ROOT / "tests" / name).is_file(), f"{name}: measured but gone; run make test-order"
    for name in DURATIONS["slow_files"]:
        text = (ROOT / "tests" / name).read_text(encoding="utf-8")
        assert "mark.slow" in text, f"{name}: measured in the slow tier but has no slow test"


def report(nodeid: str, seconds: float, *marks: str):
    return types.SimpleNamespace(nodeid=nodeid, duration=seconds, keywords=dict.fromkeys(marks, 1))


def test_an_unmeasured_file_over_a_minute_outside_the_slow_tier_fails_the_run():
    measured = next(iter(DURATIONS["files"]))
    costs = FileCosts()
    over = UNMEASURED_FILE_LIMIT_S / 2 + 1  # two phases of one test: the file's sum counts
    for nodeid, seconds, marks in [
        ("tests/envs/test_new.py::test_a", over, ()),
        ("tests/envs/test_new.py::test_a", over, ()),
        ("tests/envs/test_short.py::test_b", UNMEASURED_FILE_LIMIT_S - 1, ()),
        ("tests/envs/test_heavy.py::test_c", 10 * UNMEASURED_FILE_LIMIT_S, ("slow",)),
        (f"tests/{measured}::test_d", 10 * UNMEASURED_FILE_LIMIT_S, ()),
    ]:
        costs.pytest_runtest_logreport(report(nodeid, seconds, *marks))
    assert costs.unmeasured() == [f"envs/test_new.py took {2 * over:.0f} s"]
    session = types.SimpleNamespace(exitstatus=pytest.ExitCode.OK)
    costs.pytest_sessionfinish(session)
    assert session.exitstatus == pytest.ExitCode.TESTS_FAILED
