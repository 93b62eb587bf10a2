"""What the compilation cache saves: the same work in two fresh processes sharing one empty cache.

    python benchmarks/bench_compile_cache.py                       # quickstart and three Brax envs
    python benchmarks/bench_compile_cache.py --brax Ant Humanoid   # other Brax tasks

Rows: `contextrl run quickstart` (wall and CPU seconds of the whole command), and per Brax task the
seconds to the first result of a jitted, vmapped step over 8 contexts (compile included) in a fresh
process. The second process of each pair starts with what the first wrote to the cache.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BRAX_FIRST_STEP = """
import sys, time
import jax
from contextrl.compile_cache import use_compilation_cache
import contextrl as crl
use_compilation_cache()
env = crl.make(sys.argv[1])
contexts = env.context_space.stack([env.default_context()] * 8)
keys = jax.random.split(jax.random.key(0), 8)
start = time.perf_counter()
states, _ = jax.jit(jax.vmap(env.reset))(keys, contexts)
action = jax.numpy.zeros((8, *env.action_space.shape))
step = jax.jit(jax.vmap(env.step))
jax.block_until_ready(step(keys, states, action, contexts))
print(f"{time.perf_counter() - start:.1f}")
"""


def timed(command: list[str], cache: Path) -> tuple[float, float, str]:
    """(wall seconds, CPU seconds of the child, its last output line) of one fresh process."""
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    env["CONTEXTRL_CACHE_DIR"] = str(cache)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    lines = done.stdout.strip().splitlines()
    return wall, cpu, lines[-1] if lines else ""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--brax", nargs="*", default=["InvertedPendulum", "Hopper", "Ant"])
    args = parser.parse_args()
    contextrl = [sys.executable, "-m", "contextrl"]
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    print(f"{'work':34s} {'first':>10s} {'second':>10s} {'ratio':>7s}")
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        runs = [
            timed(
                [*contextrl, "run", "quickstart", "--quiet", "--out", str(root / f"run{i}")], root
            )
            for i in (1, 2)
        ]
        for label, index in (("quickstart wall s", 0), ("quickstart CPU s", 1)):
            first, second = runs[0][index], runs[1][index]
            print(f"{label:34s} {first:10.1f} {second:10.1f} {first / second:6.1f}x")
        for task in args.brax:
            command = [sys.executable, "-c", BRAX_FIRST_STEP, f"Brax{task}"]
            first, second = (float(timed(command, root)[2]) for _ in range(2))
            print(
                f"{'Brax' + task + ' first step s':34s} {first:10.1f} {second:10.1f} "
                f"{first / second:6.1f}x"
            )


if __name__ == "__main__":
    main()
