"""What XLA:CPU's code generation settings cost in compiling and give in running: each program compiled
and run in a fresh process with XLA's defaults, with ``--xla_cpu_use_fusion_emitters=false``, and with
that and ``--xla_backend_optimization_level=0`` (LLVM's level 0, as the test suite compiles), in turn,
no cache.

    python benchmarks/bench_compile_flags.py              # Brax Ant rollout, PPO on CartPole
    python benchmarks/bench_compile_flags.py --repeats 3

Rows: per program and setting, the seconds to compile (first call, tracing included) and the speed of
the compiled program (best of three calls). The test suite uses the last setting (tests/conftest.py):
compiling is most of its time.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys

SETTINGS = {
    "XLA's default": "",
    "fusion emitters off": "--xla_cpu_use_fusion_emitters=false",
    "emitters off, LLVM level 0": "--xla_cpu_use_fusion_emitters=false "
    "--xla_backend_optimization_level=0",
}

PROGRAM = """
import sys, time
from contextrl.xla_flags import xla_cpu_workaround
xla_cpu_workaround()
import jax
import contextrl as crl
from contextrl.agents import ppo

def brax_ant():
    env, copies, steps = crl.make("BraxAnt"), 64, 100
    contexts = env.context_space.stack([env.default_context()] * copies)
    keys = jax.random.split(jax.random.key(0), copies)

    def rollout(keys, contexts):
        states = jax.vmap(env.init)(keys, contexts)

        def body(states, key):
            actions = jax.vmap(env.action_space.sample)(jax.random.split(key, copies))
            states, reward, _ = jax.vmap(env.transition)(keys, states, actions, contexts)
            return states, reward

        return jax.lax.scan(body, states, jax.random.split(jax.random.key(1), steps))[1]

    return jax.jit(rollout), (keys, contexts), copies * steps

def ppo_cartpole():
    env = crl.make("CartPole")
    config = ppo.PPOConfig(total_timesteps=65_536, num_envs=8, num_steps=128)
    train = ppo.make_train(config, env, env.default_context())
    return jax.jit(train), (jax.random.key(0),), config.total_timesteps

function, arguments, steps = {"brax_ant": brax_ant, "ppo_cartpole": ppo_cartpole}[sys.argv[1]]()
start = time.perf_counter()
jax.block_until_ready(function(*arguments))
compile_seconds = time.perf_counter() - start
best = float("inf")
for _ in range(3):
    start = time.perf_counter()
    jax.block_until_ready(function(*arguments))
    best = min(best, time.perf_counter() - start)
print(f"{compile_seconds:.1f} {steps / best:.0f}")
"""


def measure(program: str, flags: str) -> tuple[float, float]:
    env = {**os.environ, "XLA_FLAGS": flags, "JAX_ENABLE_COMPILATION_CACHE": "false"}
    out = subprocess.run(
        [sys.executable, "-c", PROGRAM, program],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    compile_seconds, speed = out.stdout.split()[-2:]
    return float(compile_seconds), float(speed)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--programs", nargs="+", default=["brax_ant", "ppo_cartpole"])
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    print("| program | setting | run | compile s | steps/s |")
    print("| --- | --- | --- | ---: | ---: |")
    for program in args.programs:
        for repeat in range(args.repeats):
            for label, flags in SETTINGS.items():
                compile_seconds, speed = measure(program, flags)
                row = (
                    f"| {program} | {label} | {repeat + 1} | {compile_seconds:.1f} | {speed:,.0f} |"
                )
                print(row, flush=True)
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
