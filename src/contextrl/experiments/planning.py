"""``contextrl run … --dry-run``: what a spec will cost before it starts.

The plan gives the trials and chunks; the agent configs give the training steps. The time estimate
comes from earlier runs of the same spec under the run root when there are some (their recorded seconds
per chunk: no computation at all), else from one short timed call: the first chunk compiled and trained
at a small budget with the agents' progress lines on. JAX's compile events give the compile time (paid
once per group of chunks that share a compiled function), the progress lines the training rate, and the
rest of the call is the fixed (evaluation) cost of a chunk.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import time
from pathlib import Path

import jax
import yaml

from contextrl.agents import ConfigError
from contextrl.experiments.executors import PROGRESS_LINE
from contextrl.experiments.plan import Plan, expand
from contextrl.experiments.spec import CommonSpec, spec_to_dict
from contextrl.experiments.trials import TRAIN_EVAL_CONTEXTS, run_chunk

# The phases of a JAX compile as jax.monitoring reports them (tracing, lowering, XLA's compile).
COMPILE_EVENTS = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "/jax/core/compile/backend_compile_duration",
)


def duration(seconds: float) -> str:
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


def _identity(spec_data: dict) -> dict:
    """What makes two runs cost the same: the spec without its name and base seed."""
    return {k: v for k, v in spec_data.items() if k not in ("name", "seed")}


def earlier_runs(spec: CommonSpec, root: str | os.PathLike) -> list[tuple[Path, dict[str, float]]]:
    """Runs under ``root`` of this spec (name and seed aside) with recorded chunk timings, newest
    first: (run folder, seconds per chunk)."""
    mine = _identity(yaml.safe_load(yaml.safe_dump(spec_to_dict(spec), sort_keys=False)))
    found = []
    for file in Path(root).glob("*/spec.yaml"):
        timings = file.parent / "timings.json"
        if not timings.exists():
            continue
        with contextlib.suppress(OSError, yaml.YAMLError, json.JSONDecodeError):
            if _identity(yaml.safe_load(file.read_text(encoding="utf-8")) or {}) == mine:
                found.append((file.stat().st_mtime, file.parent, json.loads(timings.read_text())))
    return [(path, seconds) for _, path, seconds in sorted(found, reverse=True) if seconds]


def _compile_seconds(record: list[float]):
    """A listener adding JAX's compile durations to ``record``."""

    def listen(event: str, duration: float, **kwargs) -> None:
        if event in COMPILE_EVENTS:
            record.append(duration)

    return listen


def calibrate(spec: CommonSpec, plan: Plan) -> dict[str, float]:
    """One timed call of the first chunk at a small budget: seconds per chunk at full budget
    (``chunk``, for the first chunk's size ``size``), compile seconds per compiled group
    (``compile``), how the training time was found (``rate``: measured, or an upper bound) and how
    long the calibration took (``spent``)."""
    started = time.perf_counter()
    chunk = plan.chunks[0]
    total = _timesteps(spec, plan.trials[chunk[0]].variant)
    budget = _valid_budget(spec, max(total // 20, 1), total) if total else None
    if budget is not None:  # a short budget, with a progress line per metrics row
        options = {**spec.agent_options, "total_timesteps": budget, "progress_every": 1}
        plan = dataclasses.replace(plan, spec=dataclasses.replace(spec, agent_options=options))
    compiles: list[float] = []
    listener = _compile_seconds(compiles)
    jax.monitoring.register_event_duration_secs_listener(listener)
    lines = io.StringIO()
    try:
        with contextlib.redirect_stdout(lines):
            start = time.perf_counter()
            run_chunk(plan, chunk)
            seconds = time.perf_counter() - start
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    compile_seconds = min(sum(compiles), seconds)
    rates = [m.group(3) for m in PROGRESS_LINE.finditer(lines.getvalue()) if m.group(3) != "nan"]
    steps = budget or total  # the steps trained in the timed call (0: an untrained agent)
    if rates:
        rate = float(rates[-1].replace(",", ""))
        train = steps / rate
        fixed = max(seconds - compile_seconds - train, 0.0)
        chunk_seconds = fixed + total / rate
    else:  # no rate measured: all of the call's run time counted as training (an upper bound)
        chunk_seconds = (seconds - compile_seconds) * (total / steps if steps else 1)
    return {
        "chunk": chunk_seconds,
        "compile": compile_seconds,
        "rate": bool(rates) or not total,
        "budget": steps,
        "spent": time.perf_counter() - started,
        "size": len(chunk),
    }


def _estimate(spec: CommonSpec, plan: Plan, root: str | os.PathLike) -> tuple[float, str]:
    """Seconds the whole plan should take with the local executor, and how that was found."""
    runs = earlier_runs(spec, root)
    if runs:
        path, timings = runs[0]
        seconds = sum(timings.values()) / len(timings) * len(plan.chunks)
        return seconds, (
            f"  estimate from the timings of {len(runs)} earlier run(s) of this spec in {root} "
            f"(newest: {path}, {len(timings)} chunk(s) in {duration(sum(timings.values()))}); "
            "nothing was compiled or trained"
        )
    timing = calibrate(spec, plan)
    groups = len({plan.trials[c[0]].group(plan.sizes) for c in plan.chunks})
    chunk_seconds = sum(timing["chunk"] * len(c) / timing["size"] for c in plan.chunks)
    how = (
        "training at the measured steps/s"
        if timing["rate"]
        else "no training rate measured, so all run time counted as training: an upper bound"
    )
    return chunk_seconds + groups * timing["compile"], (
        f"  calibration: the first chunk ({timing['size']} trials) compiled once and run at "
        f"{timing['budget']:,} steps took {duration(timing['spent'])}; compile "
        f"{timing['compile']:.1f} s per compiled group ({groups}), {how}, "
        "plus the measured evaluation time per chunk"
    )


def describe_plan(
    spec: CommonSpec,
    where: str | os.PathLike,
    *,
    estimate: bool = False,
    root: str | os.PathLike = "runs",
    finished: set[int] | None = None,
) -> str:
    """The dry-run text: trials, chunks, environment steps, the run folder ``where`` and, with
    ``estimate``, a time estimate from earlier runs of this spec under ``root`` or from a short
    timed call (the only part that compiles anything). ``finished``: the chunks a run being
    resumed has finished; the text then says what is left."""
    plan = expand(spec)
    resuming = "resuming " if finished is not None else ""
    lines = [f"dry run of {resuming}{spec.protocol} ({spec.name}); nothing is written"]
    lines.append(f"  results: {where} (report.html there when the run ends)")
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
    train_steps = spec.training_steps(plan.trials)
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
    left = [c for c in range(len(plan.chunks)) if c not in (finished or set())]
    if finished is not None:
        steps_left = spec.training_steps([plan.trials[i] for c in left for i in plan.chunks[c]])
        lines.append(
            f"  finished: {len(plan.chunks) - len(left)} of {len(plan.chunks)} chunks; left: "
            f"{len(left)} chunk(s), {steps_left:,} training steps"
        )
    if not left:
        lines.append("  time: nothing left to run")
        return "\n".join(lines)
    if not estimate:
        lines.append("  time: not estimated (--estimate times it)")
        return "\n".join(lines)
    seconds, how = _estimate(spec, plan, root)
    seconds *= len(left) / len(plan.chunks)  # the chunks still to run
    lines.append(how)
    lines.append(
        f"  estimated time: {duration(seconds)} with the local executor on this machine "
        "(a rough extrapolation; Ray spreads chunks over workers)"
    )
    return "\n".join(lines)
