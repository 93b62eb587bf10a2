"""VehicleRacing: stepping speed against gymnasium's CarRacing-v3 (and CARL's), and context-switch cost.

    .venv/bin/python benchmarks/bench_vehicle_racing.py [--steps 1500] [--resets 20] [--carl]

Prints two tables:
1. steps/s of one env under the same seeded random actions (an episode restarts every 1000 steps):
   gymnasium's ``CarRacing-v3`` against ``VehicleRacing`` with the default and with non-default
   vehicles, stepped directly (``step_physics``) and through ``gymnasium.make`` (ratios to gymnasium).
   Sides run in alternating blocks so that the load of a shared machine falls on all alike. With
   ``--carl``, CARL's ``CARLVehicleRacing`` (``carl-bench``, in ``.venv-carl``, see
   ``bench_gymnasium.py``; it needs ``box2d`` and ``pygame`` there too) is timed against its own
   gymnasium's CarRacing in its own process, and compared with ours through the two ratios.
2. the cost of a context switch at reset: resets alternating between two vehicles against resets that
   keep one, and gymnasium's reset for reference (every reset lays out and builds a new track).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import time
from pathlib import Path

import gymnasium
import numpy as np
from gymnasium.envs.box2d.car_racing import CarRacing

import contextrl  # noqa: F401 - registers the gymnasium ids
from contextrl.envs.box2d import VEHICLE_NAMES, VehicleRacing

VEHICLES = ("race_car_rwd", "street_car_awd_small_trailer", "bus_fwd_large_trailer")
EPISODE = 1000

CARL_SCRIPT = """
import json, sys, time, warnings
warnings.filterwarnings("ignore")
import numpy as np
from carl.envs import CARLVehicleRacing
from gymnasium.envs.box2d.car_racing import CarRacing
steps, block, vehicle_id = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
context = dict(CARLVehicleRacing.get_default_context(), VEHICLE_ID=vehicle_id)
carl = CARLVehicleRacing(contexts={0: context})
stock = CarRacing()
carl.reset(seed=0)
stock.reset(seed=0)
# float64: with box2d 2.3.10 every CARL vehicle raises a TypeError for float32 actions
actions = np.random.default_rng(0).uniform([-1, 0, 0], [1, 1, 1], (steps, 3))
seconds = [0.0, 0.0]
for start in range(0, steps, block):
    for side, env in enumerate((carl, stock)):
        began = time.perf_counter()
        for i in range(start, min(start + block, steps)):
            env.step(actions[i])
            if (i + 1) % 1000 == 0:
                env.reset(seed=0)
        seconds[side] += time.perf_counter() - began
print(json.dumps({"carl": steps / seconds[0], "gymnasium": steps / seconds[1]}))
"""


def driving_actions(steps: int) -> np.ndarray:
    return np.random.default_rng(0).uniform([-1, 0, 0], [1, 1, 1], (steps, 3)).astype(np.float32)


def stepping(steps: int, block: int = 50) -> dict[str, float]:
    """Steps/s of every side over the same actions, timed in alternating blocks."""
    actions = driving_actions(steps)
    stock = CarRacing()
    stock.reset(seed=0)
    sides = {"gymnasium CarRacing-v3": (stock.step, lambda: stock.reset(seed=0))}
    for name in VEHICLES:
        direct = VehicleRacing()
        context = direct.context(vehicle=name)
        sides[f"direct {name}"] = (
            direct.step_physics,
            lambda env=direct, context=context: env.reset_physics(
                context, np.random.default_rng(0)
            ),
        )
        sides[f"direct {name}"][1]()
        adapter = gymnasium.make(
            "contextrl/VehicleRacing-v0", contexts={"vehicle": name}, max_steps=EPISODE + 1
        )
        adapter.reset(seed=0)
        sides[f"gymnasium.make {name}"] = (adapter.step, lambda env=adapter: env.reset(seed=0))
    seconds = dict.fromkeys(sides, 0.0)
    for start in range(0, steps, block):
        for name, (step, reset) in sides.items():
            began = time.perf_counter()
            for i in range(start, min(start + block, steps)):
                step(actions[i])
                if (i + 1) % EPISODE == 0:
                    reset()
            seconds[name] += time.perf_counter() - began
    return {name: steps / value for name, value in seconds.items()}


def carl_rates(steps: int, vehicle_id: int, block: int = 50) -> dict[str, float]:
    """Steps/s of CARL's CARLVehicleRacing and of the CarRacing of CARL's gymnasium, timed in
    alternating blocks in CARL's own virtual environment."""
    path = Path(__file__).with_name("bench_gymnasium.py")
    spec = importlib.util.spec_from_file_location("bench_gymnasium", path)
    bench_gymnasium = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench_gymnasium)
    python = bench_gymnasium.carl_python()
    if subprocess.run([str(python), "-c", "import Box2D, pygame"], capture_output=True).returncode:
        # carl-bench's own box2d extra builds box2d-py from source (needs swig): use the wheels
        subprocess.run(
            [str(python), "-m", "pip", "install", "-q", "box2d==2.3.10", "pygame"], check=True
        )
    result = subprocess.run(
        [str(python), "-c", CARL_SCRIPT, str(steps), str(block), str(vehicle_id)],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PYTHONWARNINGS": "ignore", "SDL_VIDEODRIVER": "dummy"},
    )
    return json.loads(result.stdout.strip().splitlines()[-1])


def switching(resets: int) -> tuple[float, float, float]:
    """Mean milliseconds of a reset: alternating two vehicles, keeping one, and gymnasium's."""
    env = VehicleRacing()
    contexts = (env.context(vehicle="bus_awd_large_trailer"), env.context(vehicle="tuk_tuk_rwd"))
    rng = np.random.default_rng(0)

    def mean_ms(reset) -> float:
        began = time.perf_counter()
        for i in range(resets):
            reset(i)
        return 1e3 * (time.perf_counter() - began) / resets

    stock = CarRacing()
    switch_ms = mean_ms(lambda i: env.reset_physics(contexts[i % 2], rng))
    same_ms = mean_ms(lambda i: env.reset_physics(contexts[0], rng))
    stock_ms = mean_ms(lambda i: stock.reset(seed=i))
    return switch_ms, same_ms, stock_ms


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--resets", type=int, default=20)
    parser.add_argument("--carl", action="store_true", help="also measure CARL's CARLVehicleRacing")
    args = parser.parse_args()
    print(f"CPU cores: {os.cpu_count()}\n")

    print("1. steps/s, one env, seeded random actions, an episode restarts every 1000 steps")
    rates = stepping(args.steps)
    stock = rates["gymnasium CarRacing-v3"]
    print(f"{'side':<50}{'steps/s':>9}{'vs gymnasium':>14}")
    for name, value in rates.items():
        print(f"{name:<50}{value:>9.0f}{value / stock:>14.2f}")
    if args.carl:
        print(
            "\nCARL, timed against the CarRacing of its own gymnasium in its own process "
            "(ours vs CARL = ratio of the two ratios to gymnasium)"
        )
        print(f"{'vehicle':<32}{'CARL':>7}{'gymnasium':>11}{'CARL vs gym':>13}{'ours vs CARL':>14}")
        for name in VEHICLES:
            carl = carl_rates(args.steps, VEHICLE_NAMES.index(name))
            carl_ratio = carl["carl"] / carl["gymnasium"]
            ours_ratio = rates[f"direct {name}"] / stock
            print(
                f"{name:<32}{carl['carl']:>7.0f}{carl['gymnasium']:>11.0f}{carl_ratio:>13.2f}"
                f"{ours_ratio / carl_ratio:>14.2f}"
            )

    print(f"\n2. reset, ms (mean of {args.resets}; every reset builds a new track)")
    switch_ms, same_ms, stock_ms = switching(args.resets)
    print(f"VehicleRacing, alternating bus_awd_large_trailer / tuk_tuk_rwd: {switch_ms:8.2f}")
    print(f"VehicleRacing, same vehicle (bus_awd_large_trailer):            {same_ms:8.2f}")
    print(
        f"context switch cost (difference):                               {switch_ms - same_ms:8.2f}"
    )
    print(f"gymnasium CarRacing-v3 reset:                                   {stock_ms:8.2f}")


if __name__ == "__main__":
    main()
