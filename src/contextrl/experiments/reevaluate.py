"""``contextrl eval RUN --test FEATURE=DIST``: a finished run's saved agents on new contexts.

Nothing is retrained: each trial's checkpoint is loaded, its policy rebuilt from the run's spec (the
same config and training contexts as in training, so the same context input), and every agent of a
variant is evaluated on the new contexts in one vmapped call. The rows go to
``evaluations/NAME.parquet`` (and a CSV per context) and the run's report gains a section.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import jax
import numpy as np
import pandas as pd

from contextrl.agents import evaluate, load_checkpoint
from contextrl.context.distributions import draw
from contextrl.experiments.plan import (
    ContextSet,
    context_columns,
    expand,
    stack_sets,
    trial_columns,
    trial_key,
)
from contextrl.experiments.reports import build_report
from contextrl.experiments.runs import RunDir, write_parquet
from contextrl.experiments.spec import SpecError, check_int, distribution_to_yaml
from contextrl.experiments.trials import host_context_input, host_returns

EVAL_KEY = 1_000_003


def _describe(resolved: Mapping[str, Any]) -> str:
    return ", ".join(f"{name} ~ {distribution_to_yaml(d)}" for name, d in resolved.items())


def _default_name(run: RunDir) -> str:
    taken = {p.stem for p in (run.path / "evaluations").glob("*.parquet")}
    number = 1
    while f"eval-{number}" in taken:
        number += 1
    return f"eval-{number}"


def evaluate_run(
    path: str | os.PathLike,
    test: Mapping[str, Any],
    *,
    num_contexts: int = 64,
    episodes: int | None = None,
    name: str | None = None,
    report: bool = True,
) -> tuple[Path, pd.DataFrame]:
    """Evaluate every saved agent of the run at ``path`` on ``num_contexts`` contexts drawn from
    ``test`` (feature → distribution); returns the written Parquet file and its rows."""
    run = RunDir(path)
    spec = run.spec()
    if not spec.trains_agents:
        raise SpecError(f"{run.path}: the {spec.protocol} protocol has no agents to evaluate")
    check_int("--contexts", num_contexts, 1)
    episodes = spec.eval_episodes if episodes is None else check_int("--episodes", episodes, 1)
    name = name or _default_name(run)
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
        raise SpecError(f"--name: use letters, digits, '.', '_' or '-', got {name!r}")
    resolved = spec.resolve_features("--test", test)
    env = spec.make_env()
    contexts = draw(
        env.context_space,
        resolved,
        num_contexts,
        jax.random.fold_in(jax.random.key(spec.seed), EVAL_KEY),
    )
    tested = ContextSet(name, contexts)
    plan = expand(spec)
    if not plan.trials:
        raise SpecError(
            f"{run.path}: the {spec.protocol} protocol keeps no agent per trial to evaluate"
        )
    agent = spec.agent_entry()
    folder = run.path / "checkpoints"
    trials = [t for t in plan.trials if not agent.trained or (folder / f"{t.id}.npz").exists()]
    if not trials:
        raise SpecError(f"{run.path}: no checkpoints yet; finish the run first (--resume)")
    groups: dict[tuple, list] = {}
    for trial in trials:
        groups.setdefault((trial.variant, trial.template), []).append(trial)
    frames = []
    for (variant, template_name), members in groups.items():
        template = plan.sets[template_name].contexts
        keys = [jax.random.fold_in(trial_key(spec.seed, t.id), EVAL_KEY) for t in members]
        saved = [
            load_checkpoint(folder / f"{t.id}.npz") if agent.trained else None for t in members
        ]
        if spec.host:  # host copies of the new contexts, one agent after the other
            context = host_context_input(spec, variant, env, template)
            act = jax.jit(agent.make_policy(spec.agent_config(variant), env, template).act)
            returns = np.stack(
                [
                    host_returns(spec, context, act, params, contexts, episodes, key)
                    for params, key in zip(saved, keys, strict=True)
                ]
            )
        else:  # every agent of the group in one vmapped call
            policy = agent.make_policy(spec.agent_config(variant), env, template)

            def one(params, key, policy=policy):
                return evaluate(policy, params, env, contexts, episodes, key)

            in_axes = (0 if agent.trained else None, 0)
            params = stack_sets(saved) if agent.trained else None
            vmapped = jax.jit(jax.vmap(one, in_axes=in_axes))
            returns = np.asarray(vmapped(params, jax.numpy.stack(keys)))
        for row, trial in enumerate(members):
            frames.append(
                pd.DataFrame(
                    {
                        **trial_columns(trial),
                        **context_columns(tested, env.context_space.names),
                        "return": returns[row].astype(np.float64),
                        "episodes": episodes,
                        "contexts": _describe(resolved),
                    }
                )
            )
    frame = pd.concat(frames, ignore_index=True)
    file = write_parquet(run.path / "evaluations" / f"{name}.parquet", frame)
    if report:
        build_report(run)
    return file, frame
