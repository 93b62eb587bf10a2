"""``contextrl run … --dry-run``: what a spec will cost before it starts.

The plan gives the trials and chunks; the agent configs give the training steps. The time estimate
comes from a short calibration: the first chunk trained at two small budgets, each compiled once and
then timed, gives a per-step cost and a fixed (evaluation) cost per chunk, and the compile time, which
is paid once per group of chunks that share a compiled function.
"""

from __future__ import annotations

import dataclasses
import time

from contextrl.agents import ConfigError
from contextrl.experiments.protocols import Plan, expand
from contextrl.experiments.spec import CommonSpec
from contextrl.experiments.trials import TRAIN_EVAL_CONTEXTS, run_chunk


def _duration(seconds: float) -> str:
    seconds = round(seconds)
    hours, rest = divmod(seconds, 3600)
    minutes, seconds = divmod(rest, 60)
    if hours:
        return f"{hours} h {minutes:02d} min"
    return f"{minutes} min {seconds:02d} s" if minutes else f"{seconds} s"


def _timesteps(spec: CommonSpec, variant: str) -> int:
    config = spec.agent_config(variant)
    return int(getattr(config, "total_timesteps", 0)) if config is not None else 0


def _valid_budget(spec: CommonSpec, budget: int, limit: int) -> int | None:
    """The smallest budget ≥ ``budget`` (doubling) that the agent accepts, at most ``limit``."""
    while budget <= limit:
        options = {**spec.agent_options, "total_timesteps": budget}
        try:
            spec.agent_entry().config(spec.env, options, spec.variants[0])
            return budget
        except ConfigError:
            budget *= 2
    return None


def _timed(plan: Plan, chunk: list[int]) -> tuple[float, float]:
    """(seconds of the first call: compile and run, seconds of the second: run only)."""
    start = time.perf_counter()
    run_chunk(plan, chunk)
    first = time.perf_counter() - start
    start = time.perf_counter()
    run_chunk(plan, chunk)
    return first, time.perf_counter() - start


def calibrate(spec: CommonSpec, plan: Plan) -> dict[str, float]:
    """Seconds per chunk at full budget (``chunk``, for the first chunk's size), compile seconds per
    compiled group (``compile``) and how long the calibration took (``spent``)."""
    started = time.perf_counter()
    chunk = plan.chunks[0]
    total = _timesteps(spec, plan.trials[chunk[0]].variant)
    low = _valid_budget(spec, max(total // 20, 1), total) if total else None
    if not total or low is None:
        first, run = _timed(plan, chunk)
        per_step, fixed, compile_seconds = 0.0, run, first - run
        if total:  # only the full budget is valid: it was the calibration itself
            per_step, fixed = run / total, 0.0
    else:
        points = []
        for budget in sorted({low, min(2 * low, total)}):
            options = {**spec.agent_options, "total_timesteps": budget}
            short = dataclasses.replace(spec, agent_options=options)
            points.append((budget, *_timed(dataclasses.replace(plan, spec=short), chunk)))
        (b1, first, r1), (b2, _, r2) = points[0], points[-1]
        per_step = max((r2 - r1) / (b2 - b1), 0.0) if b2 > b1 else r1 / b1
        fixed = max(r1 - per_step * b1, 0.0)
        compile_seconds = max(first - r1, 0.0)
    return {
        "chunk": fixed + per_step * total,
        "compile": compile_seconds,
        "spent": time.perf_counter() - started,
        "size": len(chunk),
    }


def describe_plan(spec: CommonSpec, *, calibrate_time: bool = True) -> str:
    """The dry-run text: trials, chunks, environment steps and (with calibration) a time estimate."""
    plan = expand(spec)
    lines = [f"dry run of {spec.protocol} ({spec.name}); nothing is written"]
    if not plan.trials:
        lines.append(
            f"  no chunks of trials: the {spec.protocol} protocol runs its own schedule "
            "(see its spec fields); no time estimate"
        )
        return "\n".join(lines)
    agent = spec.agent_entry()
    kinds = sorted({t.kind for t in plan.trials})
    lines.append(
        f"  {spec.env}, agent {spec.agent}, variants {list(spec.variants)}, {spec.seeds} seeds"
    )
    lines.append(f"  trials: {len(plan.trials)} ({', '.join(kinds)})")
    lines.append(
        f"  chunks: {len(plan.chunks)} (up to {spec.batch_size} trials trained together; "
        "a chunk is the unit written and resumed)"
    )
    train_steps = sum(_timesteps(spec, t.variant) for t in plan.trials)
    max_steps = spec.max_steps or spec.make_env().default_max_steps
    eval_steps = sum(
        (len(plan.sets[t.test_set]) + (2 * TRAIN_EVAL_CONTEXTS if agent.trained else 0))
        * spec.eval_episodes
        * max_steps
        for t in plan.trials
    )
    lines.append(
        f"  environment steps: {train_steps:,} training, at most {eval_steps:,} evaluation"
    )
    if not calibrate_time:
        return "\n".join(lines)
    timing = calibrate(spec, plan)
    groups = len({plan.trials[c[0]].group(plan) for c in plan.chunks})
    chunk_seconds = sum(timing["chunk"] * len(c) / timing["size"] for c in plan.chunks)
    estimate = chunk_seconds + groups * timing["compile"]
    lines.append(
        f"  calibration: the first chunk ({timing['size']} trials) at short budgets took "
        f"{_duration(timing['spent'])}; compile {timing['compile']:.1f} s per compiled group "
        f"({groups})"
    )
    lines.append(
        f"  estimated time: {_duration(estimate)} with the local executor on this machine "
        "(a rough extrapolation; Ray spreads chunks over workers)"
    )
    return "\n".join(lines)
