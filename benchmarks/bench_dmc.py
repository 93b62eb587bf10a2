"""dm_control family: stepping speed against dm_control itself, and the cost of a context switch.

    .venv/bin/python benchmarks/bench_dmc.py [--steps 2000] [--switches 300]

Prints two tables (vector throughput on every core: ``benchmarks/bench_host_vector.py``):
1. steps/s at the default context, random actions: ``dm_control.suite.load(...).step`` against the
   host environment stepped directly and through the gymnasium adapter (ratio to dm_control);
2. the cost of a context switch at reset: applying a context (check + model writes) and a whole reset
   alternating between two contexts, against a reset that keeps the context; plus a geometry switch
   (Finger, recompiles) and a rebuild of the model from XML (``suite.load``: what CARL does per switch).
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
from dm_control import suite  # noqa: E402

from contextrl.envs import dmc  # noqa: E402
from contextrl.gymnasium import ContextualGymEnv  # noqa: E402

SWITCH_CONTEXTS = {  # two non-geometry contexts per domain, alternated at every reset
    "walker": ({"viscosity": 0.0}, {"viscosity": 1.5, "geom_density": 1.5, "gravity": 5.0}),
    "quadruped": ({}, {"friction_tangential": 0.5, "geom_density": 1.5}),
    "fish": ({}, {"density": 2000.0, "geom_density": 1.5}),
    "finger": ({}, {"gravity": 9.81, "geom_density": 1.5}),
    "point_mass": ({}, {"mass": 1.0, "target_x": 0.1, "area_size": 0.8}),
}


def rate(function, count: int) -> float:
    """Calls per second of ``function(i)`` for i in range(count)."""
    start = time.perf_counter()
    for i in range(count):
        function(i)
    return count / (time.perf_counter() - start)


def stepping(cls, steps: int, block: int = 100) -> tuple[float, float, float]:
    """Steps/s of each side, timed in alternating blocks of ``block`` steps so that the load of a
    shared machine falls on all three alike."""
    space = cls().action_space
    actions = np.random.default_rng(0).uniform(space.low, space.high, (steps, *space.shape))
    # The same start state on both sides, so both simulate the same trajectory (the same contacts).
    stock = suite.load(
        cls.domain,
        cls.default_task,
        task_kwargs={"random": dmc.task_seed(np.random.default_rng(0))},
    )
    stock.reset()
    env = cls()
    env.reset_physics(env.default_context(), np.random.default_rng(0))
    gym_env = ContextualGymEnv(cls.__name__, max_steps=steps + 1)
    gym_env.reset(seed=0)
    gym_actions = actions.astype(np.float32)
    sides = (stock.step, env.step_physics, gym_env.step)
    seconds = np.zeros(3)
    for start in range(0, steps, block):
        for side, step in enumerate(sides):
            chunk = (gym_actions if side == 2 else actions)[start : start + block]
            began = time.perf_counter()
            for action in chunk:
                step(action)
            seconds[side] += time.perf_counter() - began
    return tuple(steps / seconds)


def switching(cls, count: int) -> tuple[float, float, float]:
    """Mean milliseconds: apply a context, reset while switching, reset without switching."""
    env = cls()
    first, second = (env.context(**values) for values in SWITCH_CONTEXTS[cls.domain])
    contexts = (first, second)
    rng = np.random.default_rng(0)

    def apply(i):  # what a switch adds to a reset: validation and the model writes
        values = env.context_values(contexts[i % 2])
        env._apply_structure(values)
        env._apply_parameters(values)

    apply_ms = 1e3 / rate(apply, count)
    switch_ms = 1e3 / rate(lambda i: env.reset_physics(contexts[i % 2], rng), count)
    same_ms = 1e3 / rate(lambda i: env.reset_physics(first, rng), count)
    return apply_ms, switch_ms, same_ms


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--switches", type=int, default=300)
    args = parser.parse_args()
    print(f"CPU cores: {os.cpu_count()}\n")

    print(
        "1. steps/s at the default context (one env, random actions, timed in alternating blocks)"
    )
    print(f"{'env':<14}{'dm_control':>12}{'direct':>10}{'ratio':>7}{'gymnasium':>11}{'ratio':>7}")
    for cls in dmc.ENVIRONMENTS:
        stock, direct, gym = stepping(cls, args.steps)
        print(
            f"{cls.__name__:<14}{stock:>12.0f}{direct:>10.0f}{direct / stock:>7.2f}"
            f"{gym:>11.0f}{gym / stock:>7.2f}"
        )

    print("\n2. context switch at reset, ms (non-geometry features, alternating two contexts)")
    print(f"{'env':<14}{'apply':>8}{'reset+switch':>14}{'reset same':>12}{'switch cost':>13}")
    for cls in dmc.ENVIRONMENTS:
        apply_ms, switch_ms, same_ms = switching(cls, args.switches)
        print(
            f"{cls.__name__:<14}{apply_ms:>8.3f}{switch_ms:>14.3f}{same_ms:>12.3f}"
            f"{switch_ms - same_ms:>13.3f}"
        )
    finger = dmc.DmcFinger()
    spinners = (finger.default_context(), finger.context(spinner_length=0.3))
    count = max(10, args.switches // 10)
    geometry_ms = 1e3 / rate(
        lambda i: finger.reset_physics(spinners[i % 2], np.random.default_rng(i)), count
    )
    rebuild_ms = 1e3 / rate(lambda i: suite.load("walker", "walk"), count)
    print(f"DmcFinger reset switching spinner_length (recompiles): {geometry_ms:.2f} ms")
    print(f"walker rebuilt from XML with suite.load (CARL's way, per switch): {rebuild_ms:.2f} ms")


if __name__ == "__main__":
    main()
