"""Host vector envs on every core: worker slices against one process, gymnasium's SyncVectorEnv and envpool.

    python benchmarks/bench_host_vector.py [--copies 8 64 256] [--workers 1] [--blocks 5] [--skip-peers]

For LunarLander, BipedalWalker, DmcWalker and RnaDesign at each number of copies (a context per copy),
copy-steps/s under seeded random actions of:
- ``HostVectorEnv`` stepping one slice here and one in each of ``--workers`` worker processes (what
  ``gymnasium.make_vec`` builds by default on a 2-core machine),
- the same in this process (``num_workers=0``, ``vectorization="sync"``),
- gymnasium's ``SyncVectorEnv`` of the single adapters (the one-process path before the workers),
timed in alternating blocks so the load of a shared machine falls on all alike (median block), and
envpool 1.2.5 (in ``.venv-envpool``) with a thread per slice, measured before and after ours
(mean of the two; LunarLander, BipedalWalker and WalkerWalk — envpool has no RNA task).
"""

from __future__ import annotations

import argparse
import functools
import os
import statistics
import sys
import time
from pathlib import Path

import gymnasium
import numpy as np
from gymnasium.vector import AutoresetMode

from contextrl.gymnasium import ContextualGymEnv, HostVectorEnv

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _peers import ENVPOOL, ENVPOOL_STEPS, run_peer  # noqa: E402

CONTEXTS = {  # (features, low, high): copy i sets them to the i-th of evenly spaced values
    "LunarLander": (("GRAVITY_Y",), -12.0, -2.0),
    "BipedalWalker": (("GRAVITY_Y",), -12.0, -6.0),
    "DmcWalker": (("gravity",), 5.0, 15.0),
    "RnaDesign": (("target_id_first", "target_id_last"), 1, 8),  # one target per copy
}
ENVPOOL_TASKS = {
    "LunarLander": "LunarLander-v2",
    "BipedalWalker": "BipedalWalker-v3",
    "DmcWalker": "WalkerWalk-v1",
}


def contexts(name: str, copies: int) -> list[dict]:
    features, low, high = CONTEXTS[name]
    kind = type(low)  # int features take whole values
    return [{f: kind(v) for f in features} for v in np.linspace(low, high, copies)]


def gymnasium_sync(name: str, copies: int, **kwargs) -> gymnasium.vector.SyncVectorEnv:
    factories = [
        functools.partial(ContextualGymEnv, name, copy_index=i, num_copies=copies, **kwargs)
        for i in range(copies)
    ]
    return gymnasium.vector.SyncVectorEnv(factories, autoreset_mode=AutoresetMode.SAME_STEP)


def timed(envs, actions) -> float:
    start = time.perf_counter()
    for action in actions:
        envs.step(action)
    return actions.shape[0] * actions.shape[1] / (time.perf_counter() - start)


def ours(name: str, copies: int, workers: int, blocks: int) -> dict[str, float]:
    """Median copy-steps/s of each variant over alternating blocks."""
    kwargs = {"contexts": contexts(name, copies)}
    variants = {
        "workers": HostVectorEnv(name, copies, num_workers=workers, **kwargs),
        "in-process": HostVectorEnv(name, copies, num_workers=0, **kwargs),
        "SyncVectorEnv": gymnasium_sync(name, copies, **kwargs),
    }
    calls = max(8, 4096 // copies)
    space = variants["workers"].action_space
    space.seed(0)
    actions = np.stack([space.sample() for _ in range(calls)])
    rates: dict[str, list[float]] = {key: [] for key in variants}
    for envs in variants.values():
        envs.reset(seed=0)
        timed(envs, actions[:2])  # first steps (and the workers' first answers) not timed
    for _ in range(blocks):
        for key, envs in variants.items():
            rates[key].append(timed(envs, actions))
    for envs in variants.values():
        envs.close()
    return {key: statistics.median(values) for key, values in rates.items()}


def envpool_rate(name: str, copies: int, threads: int) -> float | None:
    if name not in ENVPOOL_TASKS:
        return None
    calls = max(8, 4096 // copies)
    runs = [
        run_peer(ENVPOOL, ENVPOOL_STEPS, ENVPOOL_TASKS[name], copies, threads, calls)
        for _ in range(2)
    ]
    return statistics.mean(run["steps_per_s"] for run in runs)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=list(CONTEXTS))
    parser.add_argument("--copies", type=int, nargs="+", default=[8, 64, 256])
    parser.add_argument("--workers", type=int, default=1, help="worker processes beside this one")
    parser.add_argument("--blocks", type=int, default=5)
    parser.add_argument("--skip-peers", action="store_true", help="do not measure envpool")
    args = parser.parse_args(argv)
    print(f"cores: {len(os.sched_getaffinity(0))}, load average before: {os.getloadavg()[0]:.2f}")
    header = [
        "env",
        "copies",
        f"{args.workers + 1} slices",
        "in-process",
        "SyncVectorEnv",
        f"envpool ({args.workers + 1} threads)",
        "× in-process",
        "× envpool",
    ]
    rows = [header]
    for name in args.envs:
        for copies in args.copies:
            peer = None if args.skip_peers else envpool_rate(name, copies, args.workers + 1)
            rate = ours(name, copies, args.workers, args.blocks)
            rows.append(
                [
                    name,
                    str(copies),
                    f"{rate['workers']:.3g}",
                    f"{rate['in-process']:.3g}",
                    f"{rate['SyncVectorEnv']:.3g}",
                    f"{peer:.3g}" if peer else "-",
                    f"{rate['workers'] / rate['in-process']:.2f}",
                    f"{rate['workers'] / peer:.2f}" if peer else "-",
                ]
            )
            print(" | ".join(rows[-1]), flush=True)
    print(f"load average after: {os.getloadavg()[0]:.2f}\n")
    print("| " + " | ".join(header) + " |")
    print("|" + " --- |" * len(header))
    for row in rows[1:]:
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
