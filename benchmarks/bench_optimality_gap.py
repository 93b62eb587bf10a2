"""The paper's optimality-gap experiment at full size, timed: CartPole, pole length U(0.25, 0.75),
64 training contexts, one general agent and 64 specialists per seed, 10 seeds, 100,000 steps each
(650 agents), PPO with 64×64 networks (or the paper's C51 with --agent c51), through the same
`contextrl run` machinery (chunks of vmapped agents, Parquet results, report).

    python benchmarks/bench_optimality_gap.py                 # full size
    python benchmarks/bench_optimality_gap.py --max-chunks 1  # time one chunk, extrapolate the rest
    python benchmarks/bench_optimality_gap.py --agent c51 --seeds 1 --timesteps 10000 --max-chunks 1

Prints a table of agents, environment steps, wall time, agents/s and steps/s, and the measured gap.
"""

from __future__ import annotations

import argparse
import tempfile
import time

import jax

from contextrl.experiments import expand, prepare, run_experiment


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--contexts", type=int, default=64)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--timesteps", type=int, default=100_000)
    parser.add_argument("--num-envs", type=int, default=4, help="PPO environment copies per agent")
    parser.add_argument(
        "--agent",
        default="ppo",
        choices=["ppo", "c51"],
        help="c51: the paper's C51 (256×256, 51 atoms)",
    )
    parser.add_argument("--batch-size", type=int, default=128, help="agents per vmapped chunk")
    parser.add_argument("--max-chunks", type=int, default=None, help="time only this many chunks")
    parser.add_argument("--out", default=None, help="run directory (default: a temporary one)")
    args = parser.parse_args()

    spec = prepare(
        {
            "protocol": "optimality_gap",
            "name": "bench-optimality-gap",
            "env": "CartPole",
            "train": {"length": {"uniform": [0.25, 0.75]}},
            "num_contexts": args.contexts,
            "seeds": args.seeds,
            "variants": ["hidden"],
            "agent": args.agent,
            "agent_options": (
                {
                    "total_timesteps": args.timesteps,
                    "num_envs": args.num_envs,
                    "hidden_sizes": [64, 64],
                }
                if args.agent == "ppo"
                else {"total_timesteps": args.timesteps}
            ),
            "eval_episodes": 10,
            "batch_size": args.batch_size,
            "bootstrap_reps": 2000,
        }
    )
    plan = expand(spec)
    out = args.out or tempfile.mkdtemp(prefix="bench-optgap-")
    print(
        f"device: {jax.devices()[0].device_kind}, {len(plan.trials)} agents in {len(plan.chunks)} chunks"
    )
    start = time.perf_counter()
    run, summary = run_experiment(spec, out=f"{out}/run", max_chunks=args.max_chunks)
    wall = time.perf_counter() - start
    timings = run.timings()
    done = sum(len(plan.chunks[int(c)]) for c in timings)
    steps_per_agent = spec.agent_options["total_timesteps"]
    rows = [
        ("agents trained", f"{done} of {len(plan.trials)}"),
        ("environment steps (training)", f"{done * steps_per_agent:.3g}"),
        ("wall time incl. compile + report", f"{wall:.1f} s"),
        ("chunk seconds (sum)", f"{sum(timings.values()):.1f} s"),
        ("seconds per agent", f"{sum(timings.values()) / max(done, 1):.3f}"),
        ("training steps/s", f"{done * steps_per_agent / max(sum(timings.values()), 1e-9):.3g}"),
    ]
    if done < len(plan.trials) or steps_per_agent != 100_000:
        per_step = sum(timings.values()) / max(done * steps_per_agent, 1)
        rows.append(("extrapolated: 100,000 steps, 1 agent", f"{per_step * 100_000:.1f} s"))
        full = per_step * 100_000 * 650
        rows.append(("extrapolated: the paper's 650 agents", f"{full / 60:.1f} min (with compile)"))
    for chunk, seconds in sorted(timings.items(), key=lambda kv: int(kv[0])):
        rows.append((f"chunk {chunk} ({len(plan.chunks[int(chunk)])} agents)", f"{seconds:.1f} s"))
    width = max(len(name) for name, _ in rows)
    for name, value in rows:
        print(f"{name:<{width}}  {value}")
    print(f"report: {run.path / 'report.html'}")
    if summary.failed:
        print(f"failed chunks: {summary.failed}")


if __name__ == "__main__":
    main()
