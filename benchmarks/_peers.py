"""Peer libraries measured in their own virtual environments, created on first use.

CARL (``carl-bench``) and envpool pin versions that must not enter the project's environment, so each
lives in a virtual environment beside the checkout (``.venv-carl``, ``.venv-envpool``) and is measured by
running a small script there that prints one JSON line.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CARL = (".venv-carl", ("carl-bench==1.1.1",), "import carl.envs")
CARL_BOX2D = (".venv-carl", ("carl-bench==1.1.1", "box2d==2.3.10"), "import carl.envs, Box2D")
# envpool 1.2.7 has no wheel for Python 3.11 here; 1.2.5 is the newest that installs.
ENVPOOL = (".venv-envpool", ("envpool==1.2.5",), "import envpool")


def peer_python(venv: str, requirements: Sequence[str], probe: str) -> Path:
    """The interpreter of ``venv``, created (or completed) with ``requirements`` until ``probe`` runs."""
    python = ROOT / venv / "bin" / "python"
    if (
        python.exists()
        and subprocess.run([python, "-c", probe], capture_output=True).returncode == 0
    ):
        return python
    print(f"preparing {venv} with {' '.join(requirements)} (once)...", file=sys.stderr)
    if not python.exists():
        subprocess.run([sys.executable, "-m", "venv", str(ROOT / venv)], check=True)
    subprocess.run([python, "-m", "pip", "install", "-q", *requirements], check=True)
    return python


def run_peer(peer: tuple[str, Sequence[str], str], script: str, *args: object) -> dict:
    """Run ``script`` with the peer's interpreter; its last output line is a JSON object."""
    result = subprocess.run(
        [str(peer_python(*peer)), "-c", script, *map(str, args)],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PYTHONWARNINGS": "ignore"},
    )
    return json.loads(result.stdout.strip().splitlines()[-1])


# envpool stepping ``copies`` copies of ``task`` in one batch on ``threads`` threads under seeded random
# actions; prints copy-steps/s. Arguments: task, copies, threads, calls.
ENVPOOL_STEPS = """
import json, sys, time
import numpy as np
import envpool
task, copies, threads, calls = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
envs = envpool.make(task, env_type="gymnasium", num_envs=copies, batch_size=copies,
                    num_threads=threads, thread_affinity_offset=-1, seed=0)
envs.reset()
space = envs.action_space
rng = np.random.default_rng(0)
if hasattr(space, "n"):
    actions = rng.integers(0, space.n, (calls, copies))
else:
    actions = rng.uniform(space.low, space.high, (calls, copies, *space.shape)).astype(np.float32)
for action in actions[:10]:
    envs.step(action)
start = time.perf_counter()
for action in actions:
    envs.step(action)
print(json.dumps({"steps_per_s": calls * copies / (time.perf_counter() - start)}))
"""
