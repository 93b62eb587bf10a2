"""RNA design: episodes per second by target length, against the floor, ViennaRNA's fold itself.

    .venv/bin/python benchmarks/bench_rna.py [--scale 1.0]

CARL's RNA environment does not run (its ``step`` unpacks four values from a call that returns three),
so the peer is the fold: an episode designs a sequence step by step and folds it once
(``mutation_threshold=0``: no local improvement), so no environment can run more episodes per second
than ViennaRNA folds per second at that length. For
synthetic targets of 20, 50, 100, 200 and 400 nt (seeded, fixed length), random actions, the table
gives folds/s of bare ``RNA.fold`` on the designed sequences, episodes/s of the environment stepped
directly (``reset_physics``/``step_physics``) and through the gymnasium adapter, and the share of each
episode's time spent inside the fold (timed around every call). Target: ≥ 80 % for ≥ 100 nt.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import RNA

from contextrl.envs.rna import RnaDesign, design
from contextrl.gymnasium import ContextualGymEnv

LENGTHS = (20, 50, 100, 200, 400)
EPISODES = {20: 400, 50: 150, 100: 40, 200: 12, 400: 4}  # about a second of folding each
CONTEXT = {"dataset": "synthetic", "target_id_last": 20, "mutation_threshold": 0.0}


class FoldTimer:
    """Wraps the environment's fold and adds up the seconds spent inside it."""

    def __init__(self):
        self.seconds, self.calls, self.sequences = 0.0, 0, []
        self._fold = design.fold

    def __call__(self, sequence: str) -> str:
        start = time.perf_counter()
        structure = self._fold(sequence)
        self.seconds += time.perf_counter() - start
        self.calls += 1
        self.sequences.append(sequence)
        return structure

    def __enter__(self):
        design.fold = self
        return self

    def __exit__(self, *exc):
        design.fold = self._fold


def synthetic(length: int) -> dict:
    return {"lengths": (length, length), "min_multiloops": 0}


def direct(length: int, episodes: int) -> tuple[float, float, list[str]]:
    """(episodes/s, share of time in the fold, designed sequences) stepping the HostEnv itself."""
    env = RnaDesign(synthetic=synthetic(length))
    context = env.context(**CONTEXT)
    for seed in range(episodes):  # draw (and cache) the targets outside the timed part
        env.reset_physics(context, np.random.default_rng(seed))
    actions = np.random.default_rng(0).integers(0, env.action_space.n, (episodes, length)).tolist()
    with FoldTimer() as timer:
        start = time.perf_counter()
        for episode in range(episodes):
            env.reset_physics(context, np.random.default_rng(episode))
            terminated, step = False, 0
            while not terminated:
                _, _, terminated = env.step_physics(actions[episode][step])
                step += 1
        elapsed = time.perf_counter() - start
    return episodes / elapsed, timer.seconds / elapsed, timer.sequences


def through_gymnasium(length: int, episodes: int) -> tuple[float, float]:
    """(episodes/s, share of time in the fold) through ``ContextualGymEnv``."""
    env = ContextualGymEnv("RnaDesign", contexts=CONTEXT, synthetic=synthetic(length))
    env.reset(seed=0)
    for _ in range(episodes):  # draw the targets and compile the context choice first
        env.reset()
    actions = np.random.default_rng(0).integers(0, env.action_space.n, (episodes, length)).tolist()
    env.reset(seed=0)
    with FoldTimer() as timer:
        start = time.perf_counter()
        for episode in range(episodes):
            env.reset()
            terminated, step = False, 0
            while not terminated:
                _, _, terminated, _, _ = env.step(actions[episode][step])
                step += 1
        elapsed = time.perf_counter() - start
    env.close()
    return episodes / elapsed, timer.seconds / elapsed


def fold_rate(sequences: list[str]) -> float:
    """Bare ``RNA.fold`` calls per second on the same sequences: the floor."""
    start = time.perf_counter()
    for sequence in sequences:
        RNA.fold(sequence)
    return len(sequences) / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scale", type=float, default=1.0, help="multiply the episode counts")
    args = parser.parse_args()
    print(f"CPU cores: {os.cpu_count()}, ViennaRNA {RNA.__version__}\n")
    print("episodes/s by target length (random actions, one fold per episode)")
    header = (
        f"{'nt':>4}{'folds/s':>10}{'direct':>9}{'ratio':>7}{'in fold':>9}"
        f"{'gymnasium':>11}{'ratio':>7}{'in fold':>9}"
    )
    print(header)
    for length in LENGTHS:
        episodes = max(2, int(EPISODES[length] * args.scale))
        direct_rate, direct_share, sequences = direct(length, episodes)
        floor = fold_rate(sequences)
        gym_rate, gym_share = through_gymnasium(length, episodes)
        print(
            f"{length:>4}{floor:>10.0f}{direct_rate:>9.0f}{direct_rate / floor:>7.2f}"
            f"{direct_share:>8.0%} {gym_rate:>10.0f}{gym_rate / floor:>7.2f}{gym_share:>8.0%}"
        )
    print("\nratio: episodes/s over folds/s (1.00 = nothing but the fold); in fold: share of time")


if __name__ == "__main__":
    main()
