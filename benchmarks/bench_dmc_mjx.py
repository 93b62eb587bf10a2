"""dm_control on MJX against dm_control on the host: environment steps/s and agents' training steps/s.

    python benchmarks/bench_dmc_mjx.py [--envs DmcWalker,DmcPointMass] [--sizes 1,64,1024,4096]
                                       [--host-copies 16] [--agents] [--seconds 10]

1. Each task's MJX version through the project's one stepping path (``crl.with_contexts`` with
   ``reset_copies``/``step_copies``, every copy with its own context: gravity, actuator strength and,
   where the task has it, friction and the masses, drawn per copy; episodes end and restart inside
   the compiled loop) at each size, random actions, beside the host version stepped by the vector
   env (:class:`~contextrl.gymnasium.host_vector.HostVectorEnv`, one worker process per core) with the
   same kind of contexts; compile time (XLA's backend compilations, from ``jax.monitoring``) stated.
2. ``--agents``: PPO and SAC on Walker, training steps per second of the compiled call on MJX (the
   first call compiles; the second is timed) against the host path (``train_gymnasium``) at the same
   settings and budget.

Runs with XLA:CPU's concurrency-optimised scheduler off (``contextrl.xla_flags``). Prints the machine
and its load before and after.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

from contextrl.xla_flags import xla_cpu_workaround

xla_cpu_workaround()
os.environ.setdefault("MUJOCO_GL", "egl")

import jax  # noqa: E402
import numpy as np  # noqa: E402
from _contextual import contextual_rollout  # noqa: E402

import contextrl as crl  # noqa: E402

COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
compilations: list[float] = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, seconds, **_: compilations.append(seconds) if event == COMPILE_EVENT else None
)


def contexts_for(env, n: int, key):
    """``n`` contexts around the default: the dynamics features every task shares, drawn per copy."""
    features = env.context_space.features
    spec = {"actuator_strength": crl.Uniform(0.5, 1.5)}
    if "gravity" in features and features["gravity"].default > 0:
        spec["gravity"] = crl.Uniform(5.0, 15.0)
    if "friction_tangential" in features:
        spec["friction_tangential"] = crl.Uniform(0.5, 1.5)
    if "geom_density" in features:
        spec["geom_density"] = crl.Uniform(0.75, 1.5)
    if "mass" in features:
        spec["mass"] = crl.Uniform(0.2, 0.6)
    return crl.sample(env, spec, n, key)


def timed(function) -> float:
    start = time.perf_counter()
    function()
    return time.perf_counter() - start


def mjx_rate(env, n: int, seconds: float, rate_guess: float | None) -> tuple[float, float, int]:
    """(compile seconds, steps/s best of 2 calls, steps per call)."""
    steps = 10 if rate_guess is None else int(max(2, min(200, rate_guess * seconds / n)))
    run = contextual_rollout(env, n, steps)
    contexts = contexts_for(env, n, jax.random.key(1))
    before = len(compilations)
    run(jax.random.key(0), contexts).block_until_ready()
    compile_s = sum(compilations[before:])
    best = min(
        timed(lambda k=k: run(jax.random.key(k), contexts).block_until_ready()) for k in (1, 2)
    )
    return compile_s, n * steps / best, steps


def host_rate(name: str, copies: int, seconds: float) -> float:
    """Steps/s of the host version in the vector env (worker processes), per-copy contexts."""
    import gymnasium

    env = crl.make(name)
    contexts = contexts_for(env, copies, jax.random.key(1))
    rows = [
        {f: float(np.asarray(getattr(contexts, f))[i]) for f in env.context_space.names}
        for i in range(copies)
    ]
    vector = gymnasium.make_vec(f"contextrl/{name}-v0", num_envs=copies, contexts=rows)
    vector.reset(seed=0)
    space = vector.action_space
    rng = np.random.default_rng(0)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        vector.step(rng.uniform(space.low, space.high).astype(np.float32))
        steps += copies
    rate = steps / (time.perf_counter() - start)
    vector.close()
    return rate


def environment_table(names, sizes, host_copies: int, seconds: float) -> None:
    print(
        "\nSteps/s, every copy with its own context: MJX through ContextualEnv.step_copies (one "
        f"compiled call), dm_control in the host vector env ({host_copies} copies, a worker per core)"
    )
    print(
        f"{'env':>13} {'copies':>7} {'compile s':>10} {'MJX steps/s':>12} {'host steps/s':>13}"
        f" {'MJX / host':>11}"
    )
    for name in names:
        host = host_rate(name, host_copies, seconds)
        env = crl.make(name, backend="mjx")
        rate = None
        for n in sizes:
            compile_s, rate, _ = mjx_rate(env, n, seconds, rate)
            print(
                f"{name:>13} {n:>7} {compile_s:>10.1f} {rate:>12.4g} {host:>13.4g}"
                f" {rate / host:>11.2f}",
                flush=True,
            )


def agents_table(steps: int) -> None:
    from contextrl.agents import ppo, sac

    print(f"\nAgents on Walker, {steps:,} environment steps: compiled on MJX against the host path")
    print(
        f"{'agent':>6} {'MJX compile s':>14} {'MJX steps/s':>12} {'host steps/s':>13} {'ratio':>6}"
    )
    configs = {
        "PPO": (ppo, ppo.PPOConfig(total_timesteps=steps, num_envs=8, num_steps=64)),
        "SAC": (sac, sac.SACConfig(total_timesteps=steps, learning_starts=steps // 4, num_envs=1)),
    }
    for label, (module, config) in configs.items():
        env = crl.make("DmcWalker", backend="mjx")
        contexts = env.context_space.stack([env.default_context()])
        train = jax.jit(module.make_train(config, env, contexts))
        before = len(compilations)
        jax.block_until_ready(train(jax.random.key(0)))
        compile_s = sum(compilations[before:])
        mjx_seconds = timed(lambda t=train: jax.block_until_ready(t(jax.random.key(1))))
        host_seconds = timed(
            lambda m=module, c=config, x=contexts: m.train_gymnasium(
                c, "DmcWalker", x, jax.random.key(1), seed=0
            )
        )
        print(
            f"{label:>6} {compile_s:>14.1f} {steps / mjx_seconds:>12.4g} {steps / host_seconds:>13.4g}"
            f" {host_seconds / mjx_seconds:>6.2f}",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--envs", default="DmcWalker,DmcPointMass")
    parser.add_argument("--sizes", default="1,64,1024,4096")
    parser.add_argument("--host-copies", type=int, default=16)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--agents", action="store_true")
    parser.add_argument("--agent-steps", type=int, default=4096)
    args = parser.parse_args()
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, {jax.devices()[0]}"
    )
    print(f"load average at start: {os.getloadavg()}")
    names = args.envs.split(",")
    environment_table(
        names, [int(s) for s in args.sizes.split(",")], args.host_copies, args.seconds
    )
    if args.agents:
        agents_table(args.agent_steps)
    print(f"load average at end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
