"""Settings for every test process (each xdist worker and the subprocesses tests start), the ``egl``
mark (MuJoCo's headless rendering tests skip, saying why, where EGL is missing), the order in which
the two workers take the test files, and a fixture that stops a local Ray at the end of the file that
started it."""

import ctypes.util
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
# The learning tests, which run long, pin XLA's default for their own programs (tests/learning.py,
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


# The files that take longest (seconds on a fresh clone, both workers busy), handed out first: `make
# test` keeps this order (--no-loadscope-reorder) so that the short files fill in at the end and both
# workers finish together; xdist's own order (most tests first) hands out files of few long tests last.
LONGEST_FILES = (
    "test_reaching_learning.py",  # ~130: PPO on Fetch and UR5e
    "test_experiments_hpo.py",  # ~130: two PB2 runs on Ray, then the host-training tests
    "test_reaching.py",  # ~80
    "test_reaching_checker.py",  # ~80
    "test_workflow_cli.py",  # ~110
    "test_experiments_matrix.py",  # ~100, with two PB2 runs: not started beside the hpo file's
    "test_brax_large.py",  # ~85
    "test_agents_sac.py",  # ~75
    "test_paper.py",  # ~75
    "test_brax_agents.py",  # ~60
    "test_agents_dqn.py",  # ~60
    "test_platformer.py",  # ~60
    "test_brax.py",  # ~60
    "test_one_path.py",  # ~55
    "test_experiments_agents.py",  # ~45
    "test_interval_coverage.py",  # ~40: 6,000 synthetic experiments
    "test_agents_ppo.py",  # ~38
    "test_platformer_learning.py",  # ~36
    "test_experiments_runs.py",  # ~30
    "test_envs.py",  # ~30
    "test_experiments_registry.py",  # ~27
    "test_sb3.py",  # ~25
    "test_docs.py",  # ~22
    "test_face_gymnax.py",  # ~21
    "test_vehicle_racing.py",  # ~18
    "test_gymnasium.py",  # ~17
)


def pytest_collection_modifyitems(items):
    for item in items:
        if EGL_MISSING and item.get_closest_marker("egl"):
            reason = "needs EGL for MuJoCo's headless rendering (libegl1 libgl1-mesa-dri: make system-deps)"
            item.add_marker(pytest.mark.skip(reason=reason))
    rank = {name: i for i, name in enumerate(LONGEST_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: the rest keep theirs


@pytest.fixture(scope="module")
def shut_down_ray():
    """For a test file that starts a local Ray in this process (PB2, the Ray executor): stop it at
    the end of the file, so the files that follow on this worker start from no Ray."""
    yield
    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized():
        ray.shutdown()
