"""Learning curves of the built-in agents at the learning tests' budgets, many seeds in one call each.

    python benchmarks/learning_curves.py [--seeds 8]

Trains PPO and C51 on CartPole and SAC on Pendulum with the settings of tests/helpers/learning.py (the runs
whose final returns the learning tests assert), each seed in one vmapped, compiled call, and draws the
mean return of the episodes that ended in each logging period against environment steps: the median
over seeds and the band from the lowest to the highest seed. Writes docs/images/learning_curves.png and
benchmarks/results/learning_curves.md (when, where and how it was measured, the final returns), which
the documentation's agents page shows.
"""

import argparse
import datetime
import os
import pathlib
import shlex
import sys
import time

import jax
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

import contextrl as crl
from contextrl.agents import dqn, evaluate, ppo, sac
from contextrl.xla_flags import xla_cpu_workaround

ROOT = pathlib.Path(__file__).resolve().parents[1]

RUNS = {
    "PPO, CartPole": (
        "CartPole",
        ppo,
        ppo.PPOConfig(total_timesteps=100_000, num_envs=8, learning_rate=2.5e-3),
        "100,000 steps, 8 copies × 128 steps, learning rate 2.5e-3",
    ),
    "C51, CartPole": (
        "CartPole",
        dqn,
        dqn.DQNConfig(
            total_timesteps=48_000,
            num_envs=4,
            hidden_sizes=(64, 64),
            learning_starts=2000,
            target_update_interval=100,
            distributional=True,
            v_min=0.0,
            v_max=110.0,
        ),
        "48,000 steps, 4 copies, 64×64, 51 atoms on [0, 110]",
    ),
    "SAC, Pendulum": (
        "Pendulum",
        sac,
        sac.SACConfig(
            total_timesteps=16_000,
            num_envs=2,
            hidden_sizes=(64, 64),
            learning_starts=1000,
            policy_frequency=1,
        ),
        "16,000 steps, 2 copies, 1,000 warm-up transitions, 64×64",
    ),
}


def train(env_id, module, config, seeds):
    env = crl.make(env_id)
    context = env.default_context()
    keys = jax.random.split(jax.random.key(0), seeds)
    start = time.perf_counter()
    result = jax.block_until_ready(jax.jit(jax.vmap(module.make_train(config, env, context)))(keys))
    seconds = time.perf_counter() - start
    policy = module.make_policy(config, env, context)
    final = jax.jit(jax.vmap(lambda params, key: evaluate(policy, params, env, context, 10, key)))(
        result.params, jax.random.split(jax.random.key(1), seeds)
    )
    steps = np.asarray(result.metrics["step"])[0]
    curves = np.asarray(result.metrics["episode_return"])
    return steps, curves, np.asarray(final).reshape(seeds), seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--out", default=str(ROOT / "docs" / "images" / "learning_curves.png"))
    parser.add_argument(
        "--markdown", default=str(ROOT / "benchmarks" / "results" / "learning_curves.md")
    )
    args = parser.parse_args()
    command = shlex.join(["python", "benchmarks/learning_curves.py", *sys.argv[1:]])
    start_load = f"{os.getloadavg()[0]:.1f}"

    figure = Figure(figsize=(12, 3.4), layout="constrained")
    rows = []
    for index, (label, (env_id, module, config, budget)) in enumerate(RUNS.items()):
        steps, curves, final, seconds = train(env_id, module, config, args.seeds)
        print(f"{label}: {seconds:.0f} s; final returns {np.round(np.sort(final), 1).tolist()}")
        axes = figure.add_subplot(1, len(RUNS), index + 1)
        axes.fill_between(steps, np.nanmin(curves, 0), np.nanmax(curves, 0), alpha=0.25, lw=0)
        axes.plot(steps, np.nanmedian(curves, 0), lw=1.5)
        axes.set_title(f"{label} ({args.seeds} seeds)", fontsize=10)
        axes.set_xlabel("environment steps")
        axes.set_ylabel("episode return")
        axes.grid(alpha=0.3)
        rows.append(
            f"| {label} | {budget} | {seconds:.0f} s | {final.min():.1f} | "
            f"{np.median(final):.1f} | {final.max():.1f} |"
        )

    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(figure).print_png(str(out))
    cpu = next(
        (
            line.split(":", 1)[1].strip()
            for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines()
            if line.startswith("model name")
        ),
        "CPU",
    )
    text = [
        f"Measured {datetime.date.today().isoformat()} with `{command}` on {cpu}, "
        f"{os.cpu_count()} core(s), load average {start_load} at the start and "
        f"{os.getloadavg()[0]:.1f} at the end; jax {jax.__version__}. Each curve is the mean return "
        "of the episodes that ended in each logging period (the median over seeds, the band from the "
        "lowest to the highest seed); the final return is the deterministic policy's mean over 10 "
        "episodes at the default context, per seed.",
        "",
        "| run | budget | training with compilation, all seeds | final return, min | median | max |",
        "| --- | --- | --- | --- | --- | --- |",
        *rows,
    ]
    markdown = pathlib.Path(args.markdown)
    markdown.parent.mkdir(parents=True, exist_ok=True)
    markdown.write_text("\n".join(text) + "\n")
    print(f"wrote {out} and {markdown}")


if __name__ == "__main__":
    xla_cpu_workaround()
    main()
