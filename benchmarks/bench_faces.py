"""Speed of the two drop-in faces against the libraries they replace.

    python benchmarks/bench_faces.py [--copies 4096] [--steps 1000] [--single-steps 20000] [--rounds 3]

1. ``contextrl.gymnax`` in the same ``lax.scan`` loop as gymnax's own CartPole (gymnax 1.0.1 in
   ``.venv-gymnax``, built on first use by ``bench_envs.py``'s helper), every copy with its own pole
   length, on one device and split over every CPU core.
2. ``contextrl.carl``'s ``CARLCartPole`` against CARL 1.1.1's (``.venv-carl``, built on first use by
   ``bench_gymnasium.py``'s helper), one env, random actions, finished episodes reset; both with CARL's
   default observation (every feature, as a dict).
"""

from __future__ import annotations

import argparse

import jax
from _scan import CORES, random_rollout, steps_per_second
from bench_envs import gymnax_rate
from bench_gymnasium import bench_carl, bench_single

import contextrl as crl
import contextrl.gymnax as gymnax
from contextrl.carl.envs import CARLCartPole


def gymnax_face_rate(copies: int, steps: int, devices: int) -> float:
    """Steps/s of the gymnax face in the loop gymnax_cartpole.py runs for gymnax."""
    env, params = gymnax.make("CartPole-v1")
    batch = crl.sample(params, {"length": crl.Uniform(0.25, 0.75)}, copies, jax.random.key(0))

    def reset(key, p):
        obs, state = env.reset(key, p)
        return state, obs

    def step(key, state, action, p):
        obs, state, *_ = env.step(key, state, action, p)
        return state, obs

    sample = env.action_space(params).sample
    run = random_rollout(reset, step, sample, batch, steps, devices=devices)
    return steps_per_second(run, copies, steps)[1]


def table(title: str, rows: list[tuple[str, float]], baseline: float, against: str) -> None:
    width = max(len(name) for name, _ in rows)
    print(f"\n{title}")
    print(f"{'what'.ljust(width)}  {'steps/s':>10}  × {against}")
    for name, rate in rows:
        print(f"{name.ljust(width)}  {rate:10.3e}  {rate / baseline:6.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, default=4096)
    parser.add_argument("--steps", type=int, default=1000, help="steps per copy (batched rows)")
    parser.add_argument("--single-steps", type=int, default=20_000, help="steps of the single env")
    parser.add_argument("--rounds", type=int, default=3, help="interleaved rounds; best kept")
    args = parser.parse_args()
    print(f"jax {jax.__version__} on {jax.devices()[0].platform}, {CORES} CPU core(s)")

    # The machine may be shared: rounds alternate which library goes first; each row keeps its best.
    best: dict[tuple[str, int], float] = {}
    measures = {"gymnax": gymnax_rate, "contextrl": gymnax_face_rate}
    for round_index in range(args.rounds):
        order = list(measures) if round_index % 2 == 0 else list(reversed(measures))
        for devices in sorted({1, CORES}):
            for library in order:
                rate = measures[library](args.copies, args.steps, devices)
                best[library, devices] = max(best.get((library, devices), 0.0), rate)
    rows = []
    for devices in sorted({1, CORES}):
        where = "1 device" if devices == 1 else f"{devices} devices"
        rows += [(f"gymnax 1.0.1 CartPole-v1, {where}", best["gymnax", devices])]
        rows += [(f"contextrl.gymnax CartPole, {where}", best["contextrl", devices])]
    gymnax_one_device = rows[0][1]
    table(
        f"gymnax face, {args.copies} copies each with its own pole length, {args.steps} steps",
        rows,
        gymnax_one_device,
        "gymnax (1 device)",
    )
    for i in range(0, len(rows), 2):
        print(f"  same devices: contextrl.gymnax / gymnax = {rows[i + 1][1] / rows[i][1]:.2f}")

    singles = {
        "CARL 1.1.1 CARLCartPole()": lambda: bench_carl(args.single_steps),
        "contextrl.carl CARLCartPole()": lambda: bench_single(CARLCartPole(), args.single_steps),
        "contextrl.carl CARLCartPole(obs_context_as_dict=False)": lambda: bench_single(
            CARLCartPole(obs_context_as_dict=False), args.single_steps
        ),
    }
    best_single = dict.fromkeys(singles, 0.0)
    for round_index in range(args.rounds):
        names = list(singles) if round_index % 2 == 0 else list(reversed(singles))
        for name in names:
            best_single[name] = max(best_single[name], singles[name]())
    rows = list(best_single.items())
    carl = rows[0][1]
    table(f"CARL face, one env, {args.single_steps} random steps", rows, carl, "CARL")


if __name__ == "__main__":
    main()
