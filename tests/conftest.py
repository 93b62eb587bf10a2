"""Settings for every test process (each xdist worker and the subprocesses tests start), the tiers
(``quick``: `make test-quick`, after every edit; ``slow``: `make test-slow`, the tests that cannot be made
cheap), the ``egl`` mark (MuJoCo's headless rendering tests skip, saying why, where EGL is missing), the
order in which the two workers take the test files, the guard that keeps a file's cost a decision, and a
fixture that stops a local Ray at the end of the file that started it."""

import ctypes.util
import json
import os
import sys
from pathlib import Path

import jax
import pytest

from contextrl.xla_flags import xla_cpu_workaround

ROOT = Path(__file__).resolve().parents[1]

xla_cpu_workaround()  # before any test starts JAX's CPU backend (see README, process-wide settings)

# Compiling, not running, is most of the suite's time. Two XLA:CPU settings cut it:
# - without the fusion emitters (XLA's older emitters) a Brax parity program compiles in 24 s instead
#   of 40 s; compiled programs run as fast on MJX but PPO's loop at about 0.55×
#   (benchmarks/bench_compile_flags.py);
# - LLVM's optimisation level 0 instead of 3: test_brax.py's Hopper test takes 14 s instead of 19 s,
#   the optimality-gap and paper tests that train at tiny budgets 24 s instead of 62 s.
# The learning tests, which run long, pin XLA's default for their own programs (tests/helpers/learning.py,
# MEASURED_NUMERICS); elsewhere results differ in the last bits only. Subprocesses that tests start
# (the CLI, process executors, Ray workers) inherit the flags.
for flag in ("--xla_cpu_use_fusion_emitters=false", "--xla_backend_optimization_level=0"):
    if flag.split("=")[0] not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] += f" {flag}"

# One on-disk JAX compilation cache for every process of the suite: the xdist workers, and the CLI
# runs and process executors that tests start (JAX reads these variables when it is imported), so a
# program compiled once is loaded everywhere else, and a second `make test` compiles little.
# Programs are keyed by their HLO, the jaxlib version and the XLA flags, so a stale entry is never
# used; `pytest --cache-clear` does not remove it, deleting the folder does.
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(ROOT / ".pytest_cache" / "jax"))
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.3")
jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
jax.config.update(
    "jax_persistent_cache_min_compile_time_secs",
    float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]),
)


EGL_MISSING = ctypes.util.find_library("EGL") is None


def pytest_configure(config):
    config.addinivalue_line("markers", "egl: renders with MuJoCo headless, which needs EGL")
    config.addinivalue_line(
        "markers", "quick: in `make test-quick` (no learning, no large compiles)"
    )
    config.addinivalue_line(
        "markers",
        "slow: in `make test-slow` only; cannot be made cheap without losing what it proves",
    )
    if not hasattr(config, "workerinput"):  # the controller, or a run without xdist
        config.pluginmanager.register(FileCosts(), "file_costs")


# The order in which the two workers take the test files: longest first, as measured in a fresh clone's
# `make test` and `make test-slow` and written by `make test-order` (tools/order_tests.py, which also
# keeps the two PB2 files from running at the same time). The make targets keep this order
# (--no-loadscope-reorder) so that the short files fill in at the end and both workers finish together;
# xdist's own order (most tests first) hands out files of few long tests last. A file not yet measured
# goes after the others.
DURATIONS = json.loads((ROOT / "tests" / "file_durations.json").read_text(encoding="utf-8"))
MEASURED = {tier: DURATIONS.get(tier, {}) for tier in ("files", "slow_files")}
# A file whose tests take longer than this in one run, outside the slow tier, must have been measured
# (be in tests/file_durations.json), so that its cost counts in the budget by decision, not by accident.
UNMEASURED_FILE_LIMIT_S = 60.0


def file_of(item_or_nodeid) -> str:
    """The test file of an item or a report's node id, relative to tests/ (``envs/dmc/test_dmc.py``)."""
    nodeid = getattr(item_or_nodeid, "nodeid", item_or_nodeid)
    return nodeid.split("::")[0].removeprefix("tests/")


@pytest.hookimpl(trylast=True)  # after `-m` has deselected: the tier is what is left
def pytest_collection_modifyitems(items):
    for item in items:
        if EGL_MISSING and item.get_closest_marker("egl"):
            reason = "needs EGL for MuJoCo's headless rendering (libegl1 libgl1-mesa-dri: make system-deps)"
            item.add_marker(pytest.mark.skip(reason=reason))
    slow_tier = bool(items) and all(item.get_closest_marker("slow") for item in items)
    rank = {name: i for i, name in enumerate(MEASURED["slow_files" if slow_tier else "files"])}
    items.sort(key=lambda item: rank.get(file_of(item), len(rank)))  # stable


class FileCosts:
    """Sums each file's seconds in this run (setup, call and teardown: a module fixture's compile
    counts) from the reports, which reach the controller under xdist, and fails the run when a file's
    tests outside the slow tier took over UNMEASURED_FILE_LIMIT_S and the file was never measured."""

    def __init__(self):
        self.seconds: dict[str, float] = {}

    def pytest_runtest_logreport(self, report):
        if "slow" not in report.keywords:
            name = file_of(report.nodeid)
            self.seconds[name] = self.seconds.get(name, 0.0) + report.duration

    def unmeasured(self) -> list[str]:
        known = MEASURED["files"].keys() | MEASURED["slow_files"].keys()
        return [
            f"{name} took {seconds:.0f} s"
            for name, seconds in sorted(self.seconds.items())
            if seconds > UNMEASURED_FILE_LIMIT_S and name not in known
        ]

    def pytest_terminal_summary(self, terminalreporter):
        for line in self.unmeasured():
            terminalreporter.write_line(
                f"{line} outside the slow tier and is not in tests/file_durations.json: mark its "
                "expensive tests slow, or measure it (make test-order) so the budget counts it",
                red=True,
            )

    @pytest.hookimpl(trylast=True)
    def pytest_sessionfinish(self, session):
        if self.unmeasured() and session.exitstatus == pytest.ExitCode.OK:
            session.exitstatus = pytest.ExitCode.TESTS_FAILED


@pytest.fixture(scope="module")
def shut_down_ray():
    """For a test file that starts a local Ray in this process (PB2, the Ray executor): stop it at
    the end of the file, so the files that follow on this worker start from no Ray."""
    yield
    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized():
        ray.shutdown()
