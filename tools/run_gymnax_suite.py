"""Run gymnax's own tests against ``contextrl.gymnax.v1``, with only ``import gymnax`` changed.

The tests stay in gymnax's checkout (FOLDER: RobertTLange/gymnax at its 1.0.1 release): ``tests/`` is copied
to a temporary folder, each ``import gymnax`` becomes ``import contextrl.gymnax.v1 as gymnax`` (gymnax
1.0's six-value step), and pytest runs there with the checkout's own package first on the path, because
the tests also import gymnax's modules (its spaces, wrappers and state classes), which stay gymnax's.
Only tests that build an environment both libraries have are counted (the classic-control five, with
``--all``): tests of gymnax-only environments and of gymnax's own base class are deselected, and so are
the registry-wide test's contextrl-only ids. Nothing is fetched.

    git clone https://github.com/RobertTLange/gymnax /tmp/gymnax
    pip install --target /tmp/gymnax-test-deps --no-deps chex toolz    # gymnax's test extra
    .venv/bin/python tools/run_gymnax_suite.py /tmp/gymnax --path /tmp/gymnax-test-deps

It prints pytest's report and a last line ``gymnax suite on contextrl.gymnax.v1: P of N passed``; the
migration guide (docs/migration-gymnax.md) records the count and why each failure differs.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

SUITE = (
    "classic_control/test_gym_env.py",
    "test_terminal_states.py",
    "test_reproduction_matrix.py",
    "test_differentiability.py",
    "test_registration.py",
    "wrappers/test_gym.py",
)
# Tests of environments only gymnax has (its misc family) and of gymnax's own base class, which build
# nothing through ``gymnax.make``: not about the face, so not counted.
NOT_SHARED = (
    "test_differentiability.py::test_supported_environments_expose_finite_observation_gradients"
    "[PointRobot-misc]",
    "test_differentiability.py::test_supported_environments_expose_finite_observation_gradients"
    "[Reacher-misc]",
    "test_differentiability.py::test_supported_environments_expose_finite_observation_gradients"
    "[Swimmer-misc]",
    "test_differentiability.py::test_point_robot_preserves_position_dynamics_gradients_away_from_respawn",
    "wrappers/test_gym.py::test_gym_wrapper",
    "wrappers/test_gym.py::test_gym_vector_wrapper",
    "test_terminal_states.py::test_step_env_terminated_result_controls_autoreset",
    "test_terminal_states.py::test_pytree_observations_survive_autoreset_jit_and_vmap",
)
GYMNAX_IMPORT = re.compile(r"^import gymnax$", re.MULTILINE)
# pytest's --deselect takes prefixes (``::test_gym_wrapper`` would drop ``::test_gym_wrapper_forwards_*``
# too), so the tests above are left out by exact id, by this plugin.
PLUGIN = """
NOT_SHARED = {not_shared!r}


def pytest_collection_modifyitems(config, items):
    left_out = [item for item in items if item.nodeid in NOT_SHARED]
    config.hook.pytest_deselected(items=left_out)
    items[:] = [item for item in items if item.nodeid not in NOT_SHARED]
"""


def only_shared() -> str:
    """A ``-k`` expression leaving out contextrl's environments that gymnax does not have."""
    from contextrl.gymnax import GYMNAX_IDS, registered_envs

    ours = [name for name in registered_envs if name not in GYMNAX_IDS.values()]
    return " and ".join(f"not {name}" for name in ours)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a checkout of RobertTLange/gymnax (1.0.1)")
    parser.add_argument("pytest_args", nargs="*", help="passed on to pytest (after --)")
    parser.add_argument(
        "--path", action="append", default=[], help="a folder of the tests' own dependencies (chex)"
    )
    args = parser.parse_args()
    if not (args.folder / "tests" / SUITE[0]).is_file():
        parser.error(f"folder {args.folder}: no tests/{SUITE[0]}; give a checkout of gymnax")
    with tempfile.TemporaryDirectory(prefix="gymnax-suite-") as work:
        tests = Path(work) / "tests"
        shutil.copytree(args.folder / "tests", tests)
        for path in tests.rglob("*.py"):
            text = path.read_text(encoding="utf-8")
            path.write_text(
                GYMNAX_IMPORT.sub("import contextrl.gymnax.v1 as gymnax", text), encoding="utf-8"
            )
        not_shared = {f"tests/{test}" for test in NOT_SHARED}
        (Path(work) / "not_shared.py").write_text(PLUGIN.format(not_shared=not_shared))
        command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-o", "addopts="]
        path = os.pathsep.join([work, str(args.folder.resolve()), *args.path])
        result = subprocess.run(
            [*command, "-p", "not_shared", "--rootdir", work, "--all", "-k", only_shared()]
            + [*args.pytest_args, *(f"tests/{name}" for name in SUITE)],
            cwd=work,
            capture_output=True,
            text=True,
            env={**os.environ, "PYTHONPATH": path},
        )
    print(result.stdout + result.stderr, end="")
    last = result.stdout.strip().splitlines()[-1] if result.stdout.strip() else ""
    counts = {word: int(n) for n, word in re.findall(r"(\d+) (passed|failed|errors?)", last)}
    print(
        f"gymnax suite on contextrl.gymnax.v1: {counts.get('passed', 0)} of {sum(counts.values())} passed"
    )
    return result.returncode


if __name__ == "__main__":
    raise SystemExit(main())
