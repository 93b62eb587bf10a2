"""Settings for every test process (each xdist worker and the subprocesses tests start), the ``egl``
mark (MuJoCo's headless rendering tests skip, saying why, where EGL is missing), the order in which
the two workers take the test files, and a fixture that stops a local Ray at the end of the file that
started it."""

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


# The order in which the two workers take the test files: longest first, as measured in a whole `make
# test` and written by `python tools/order_tests.py .pytest_cache/junit.xml` (which also keeps the two
# PB2 files from running at the same time). `make test` keeps this order (--no-loadscope-reorder) so
# that the short files fill in at the end and both workers finish together; xdist's own order (most
# tests first) hands out files of few long tests last. A file not yet measured goes after the others.
FILE_ORDER = list(
    json.loads((ROOT / "tests" / "file_durations.json").read_text(encoding="utf-8"))["files"]
)


def pytest_collection_modifyitems(items):
    for item in items:
        if EGL_MISSING and item.get_closest_marker("egl"):
            reason = "needs EGL for MuJoCo's headless rendering (libegl1 libgl1-mesa-dri: make system-deps)"
            item.add_marker(pytest.mark.skip(reason=reason))
    rank = {name: i for i, name in enumerate(FILE_ORDER)}
    tests = ROOT / "tests"
    items.sort(
        key=lambda item: rank.get(item.path.relative_to(tests).as_posix(), len(rank))
    )  # stable


@pytest.fixture(scope="module")
def shut_down_ray():
    """For a test file that starts a local Ray in this process (PB2, the Ray executor): stop it at
    the end of the file, so the files that follow on this worker start from no Ray."""
    yield
    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized():
        ray.shutdown()
