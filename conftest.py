"""Settings for every test process (each xdist worker and the subprocesses tests start), the README's
Python blocks collected as tests by Sybil (a stale snippet fails the suite), and the ``egl`` mark:
MuJoCo's headless rendering tests skip, saying why, where EGL is missing."""

import ctypes.util
import doctest
import os
from pathlib import Path

import jax
import pytest
from sybil import Sybil
from sybil.parsers.markdown import PythonCodeBlockParser, SkipParser

from contextrl.xla_flags import xla_cpu_workaround

ROOT = Path(__file__).resolve().parent

xla_cpu_workaround()  # before any test starts JAX's CPU backend (see README, process-wide settings)

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


@pytest.fixture(scope="module")
def readme_folder(tmp_path_factory):
    """The README's blocks run in an empty folder (they write checkpoints under runs/)."""
    folder = tmp_path_factory.mktemp("readme")
    before = Path.cwd()
    os.chdir(folder)
    yield folder
    os.chdir(before)


pytest_collect_file = Sybil(
    parsers=[PythonCodeBlockParser(doctest_optionflags=doctest.NORMALIZE_WHITESPACE), SkipParser()],
    patterns=["README.md"],
    fixtures=["readme_folder"],
).pytest()


EGL_MISSING = ctypes.util.find_library("EGL") is None


def pytest_configure(config):
    config.addinivalue_line("markers", "egl: renders with MuJoCo headless, which needs EGL")


@pytest.hookimpl(tryfirst=True)  # before xdist reads the groups
def pytest_collection_modifyitems(items):
    for item in items:
        if item.path.name == "README.md":  # one namespace, block after block, on one worker
            item.add_marker(pytest.mark.xdist_group("readme"))
        if EGL_MISSING and item.get_closest_marker("egl"):
            reason = "needs EGL for MuJoCo's headless rendering (libegl1 libgl1-mesa-dri: make system-deps)"
            item.add_marker(pytest.mark.skip(reason=reason))
