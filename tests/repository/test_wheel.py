"""The package beside other versions: the wheel and the sdist build, and the wheel, installed with
``[agents,experiments]`` into a fresh virtual environment beside an older optax than the one the
test suite pins (a version the package's range allows), runs the main job and lists the paper's
figures from outside the checkout, with its package data (specs, the environment index, the RNA
targets) inside the wheel; the figures of the simulators not installed name the extra they need. And
the quick tier passes with the oldest core versions the package allows."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

from tests.helpers import ROOT

pytestmark = pytest.mark.slow

OLDER_OPTAX = "0.2.6"  # the package allows optax>=0.2.6,<0.3; constraints.txt pins 0.2.8
# The oldest core versions the package (and JAX 0.10.2, which needs scipy>=1.14 and ml_dtypes>=0.5)
# allows, at their last patch release
OLDEST_CORE = {"numpy": "2.0.2", "scipy": "1.14.1", "ml_dtypes": "0.5.0"}


def _run(*command, cwd: Path, env: dict | None = None) -> str:
    done = subprocess.run(
        [str(c) for c in command], cwd=cwd, env=env, capture_output=True, text=True, timeout=1200
    )
    assert done.returncode == 0, f"{' '.join(map(str, command))}\n{done.stdout}\n{done.stderr}"
    return done.stdout + done.stderr


def _pins(names: set[str]) -> list[str]:
    """constraints.txt's exact versions, but for ``names`` (given their own)."""
    lines = (ROOT / "constraints.txt").read_text(encoding="utf-8").splitlines()
    return [
        line
        for line in lines
        if line.strip() and not line.startswith("#") and re.split(r"[=<>\[ ]", line)[0] not in names
    ]


def test_the_wheel_runs_the_main_job_in_a_fresh_environment(tmp_path):
    dist = tmp_path / "dist"
    _run(sys.executable, "-m", "build", "--wheel", "--sdist", "--outdir", dist, ROOT, cwd=tmp_path)
    (wheel,) = dist.glob("contextrl-*.whl")
    (sdist,) = dist.glob("contextrl-*.tar.gz")
    names = zipfile.ZipFile(wheel).namelist()
    for data in ("contextrl/paper/specs/ecdf_pendulum.yaml", "contextrl/environments.json"):
        assert data in names, data
    assert any(n.startswith("contextrl/envs/rna/data/") and n.endswith(".txt") for n in names)
    with tarfile.open(sdist) as archive:
        assert any(
            n.endswith("src/contextrl/paper/specs/ecdf_pendulum.yaml") for n in archive.getnames()
        )

    venv = tmp_path / "venv"
    _run(sys.executable, "-m", "venv", venv, cwd=tmp_path)
    python = venv / "bin" / "python"
    constraints = tmp_path / "constraints.txt"
    constraints.write_text("\n".join(_pins({"optax", "contextrl"})) + "\n", encoding="utf-8")
    _run(
        python, "-m", "pip", "install", "-q", "-c", constraints,
        f"{wheel}[agents,experiments]", f"optax=={OLDER_OPTAX}", cwd=tmp_path,
    )  # fmt: skip
    shown = _run(python, "-m", "pip", "show", "optax", cwd=tmp_path)
    assert f"Version: {OLDER_OPTAX}" in shown

    env = {**os.environ, "PYTHONPATH": ""}  # nothing from the checkout
    contextrl = venv / "bin" / "contextrl"
    where = _run(python, "-c", "import contextrl; print(contextrl.__file__)", cwd=tmp_path, env=env)
    assert str(venv) in where and str(ROOT) not in where
    out = _run(
        contextrl, "run", "quickstart", "--timesteps", "2048", "--seeds", "1", "--episodes", "1",
        "--out", tmp_path / "run", "--quiet", cwd=tmp_path, env=env,
    )  # fmt: skip
    assert (tmp_path / "run" / "report.html").exists(), out
    listing = _run(contextrl, "paper", cwd=tmp_path, env=env)
    assert "ecdf_pendulum" in listing and "steps (small): 60,000" in listing, listing
    assert 'the dmc family, whose simulator is not installed: pip install "contextrl[dmc]"' in (
        listing
    )


def test_the_quick_tier_passes_with_the_oldest_core_versions_allowed(tmp_path):
    """numpy, scipy and ml_dtypes at the lower bounds the package declares (pyproject.toml) and JAX
    needs, put first on the path of the suite's own environment: the quick tier passes."""
    declared = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    for name in ("numpy", "scipy"):
        lower = re.search(rf'"{name}>=([\d.]+)', declared).group(1)
        assert OLDEST_CORE[name].startswith(lower + "."), (name, lower)
    older = tmp_path / "older"
    pins = [f"{name}=={version}" for name, version in OLDEST_CORE.items()]
    _run(sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", older, *pins,
         cwd=tmp_path)  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(older)}
    found = _run(sys.executable, "-c", "import numpy, scipy; print(numpy.__version__, scipy.__version__)",
                 cwd=tmp_path, env=env)  # fmt: skip
    assert found.split() == [OLDEST_CORE["numpy"], OLDEST_CORE["scipy"]]
    out = _run(sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", "quick",
               "-n", "2", cwd=ROOT, env=env)  # fmt: skip
    assert re.search(r"\d+ passed", out), out
