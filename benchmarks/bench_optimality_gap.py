"""The paper's optimality-gap experiment at full size, timed: CartPole, pole length U(0.25, 0.75),
64 training contexts, one general agent and 64 specialists per seed, 10 seeds, 100,000 steps each
(650 agents), PPO with 64×64 networks (or the paper's C51 with --agent c51), through the same
`contextrl run` machinery (chunks of vmapped agents, Parquet results, report). By default chunks run on
the ``processes`` executor: one worker process per CPU core, each training whole chunks of 64 agents.

    python benchmarks/bench_optimality_gap.py --full          # the paper's setting end to end
    python benchmarks/bench_optimality_gap.py --contexts 8    # 1 general + 8 specialists × 10 seeds
    python benchmarks/bench_optimality_gap.py --executor local --max-chunks 1  # one chunk, here
    python benchmarks/bench_optimality_gap.py --agent c51 --seeds 1 --timesteps 10000 --max-chunks 1

Prints a table of agents, environment steps, wall time (compile, training, evaluation and report),
seconds per agent and steps/s, and, for a fraction of the paper's setting, the wall time extrapolated
to its 650 agents.
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
    parser.add_argument("--batch-size", type=int, default=64, help="agents per vmapped chunk")
    parser.add_argument(
        "--executor",
        default="processes",
        choices=["processes", "local"],
        help="processes: one worker per CPU core; local: every chunk in this process",
    )
    parser.add_argument(
        "--full",
        action="store_true",
        help="the paper's setting: 64 contexts, 10 seeds, 100,000 steps (overrides those options)",
    )
    parser.add_argument("--max-chunks", type=int, default=None, help="time only this many chunks")
    parser.add_argument("--out", default=None, help="run directory (default: a temporary one)")
    args = parser.parse_args()
    if args.full:
        args.contexts, args.seeds, args.timesteps, args.max_chunks = 64, 10, 100_000, None

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
        f"device: {jax.devices()[0].device_kind}, {len(plan.trials)} agents in {len(plan.chunks)} "
        f"chunks, executor {args.executor}"
    )
    start = time.perf_counter()
    run, summary = run_experiment(
        spec, out=f"{out}/run", executor=args.executor, max_chunks=args.max_chunks
    )
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
    paper = 650 * 100_000
    if done * steps_per_agent != paper:
        per_step = sum(timings.values()) / max(done * steps_per_agent, 1)
        rows.append(("chunk seconds per 100,000 steps, 1 agent", f"{per_step * 100_000:.2f} s"))
        full = wall * paper / max(done * steps_per_agent, 1)
        rows.append(
            (
                "extrapolated wall: the paper's 650 agents",
                f"{full / 60:.1f} min (compile scaled too)",
            )
        )
    else:
        rows.append(("the paper's full optimality gap", f"{wall / 60:.1f} min (target ≤ 10 min)"))
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
