"""Run one chunk of trials: every trial of the chunk trains and is evaluated in one vmapped call.

The agent adapter hides what differs between agents ("ppo", "dqn", "c51": contextrl's agents; "random":
uniform random actions, a no-training baseline and the cheap agent for smoke tests). A chunk returns plain tables, so
it can run in this process or on a Ray worker.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import jax
import numpy as np
import pandas as pd

from contextrl.experiments.protocols import Plan, stack_sets, trial_key
from contextrl.experiments.spec import SpecError


@dataclasses.dataclass
class ChunkResult:
    """Evaluation rows (one per trial × test context), training-curve rows and trained parameters."""

    evaluations: pd.DataFrame
    curves: pd.DataFrame
    params: list[Any]
    seconds: float


def agent_config(spec, variant: str):
    """The agent's config from the spec's agent options with this visibility variant (validated).

    "ppo": PPOConfig; "dqn": DQNConfig; "c51": the paper's C51 setting for the environment where the
    paper has one (else DQNConfig with the distributional head), options overriding either.
    """
    from contextrl.agents import ConfigError, dqn, ppo

    options = dict(spec.agent_options)
    config_type = ppo.PPOConfig if spec.agent == "ppo" else dqn.DQNConfig
    fields = {f.name for f in dataclasses.fields(config_type)}
    unknown = sorted(set(options) - fields)
    if unknown:
        raise SpecError(
            f"agent_options: unknown {spec.agent} option(s) {unknown}; valid: {sorted(fields)}"
        )
    options["context_obs"] = variant
    try:
        if spec.agent == "c51" and spec.env in dqn.PAPER_C51:
            config = dqn.paper_config(spec.env, **options)
        elif spec.agent == "c51":
            config = dqn.DQNConfig(**{"distributional": True, **options})
        else:
            config = config_type(**options)
        config.validate()
    except (ConfigError, TypeError) as error:
        raise SpecError(f"agent_options: {error}") from None
    return config


def _agent_module(name: str):
    from contextrl.agents import dqn, ppo

    return ppo if name == "ppo" else dqn


def check_agent(spec) -> None:
    """Refuse bad agent options before anything runs."""
    if spec.agent != "random":
        for variant in spec.variants:
            agent_config(spec, variant)
    elif spec.agent_options:
        raise SpecError(
            f"agent_options: the {spec.agent} agent takes none, got {spec.agent_options}"
        )


_COMPILED: dict[tuple, Any] = {}


def _compiled(spec, variant: str, env, template):
    """The jitted, vmapped train-and-evaluate function; chunks of the same shape share one compile.

    Only the structure of ``template`` matters (its size and which features vary), so it is the key.
    """
    key = (
        spec.env,
        spec.max_steps,
        spec.agent,
        repr(sorted(spec.agent_options.items())),
        spec.eval_episodes,
        variant if spec.agent != "random" else "",  # the random policy ignores the context
        len(template),
        env.context_space.varying(template) if len(template) > 1 else (),
    )
    if key in _COMPILED:
        return _COMPILED[key]
    from contextrl.agents import evaluate

    episodes = spec.eval_episodes
    if spec.agent == "random":

        def random_policy(params, obs, ctx, key):
            return env.action_space.sample(key)

        def one(key, train_ctx, test_ctx):
            returns = evaluate(random_policy, None, env, test_ctx, episodes, key)
            return returns, jax.numpy.zeros(0), jax.numpy.zeros(0), None

    else:
        agent = _agent_module(spec.agent)
        config = agent_config(spec, variant)
        train = agent.make_train(config, env, template)
        policy = agent.make_policy(config, env, template)

        def one(key, train_ctx, test_ctx):
            train_key, eval_key = jax.random.split(key)
            result = train(train_key, train_ctx)
            returns = evaluate(policy, result.params, env, test_ctx, episodes, eval_key)
            return returns, result.metrics["step"], result.metrics["episode_return"], result.params

    _COMPILED[key] = jax.jit(jax.vmap(one))
    return _COMPILED[key]


def _train_and_evaluate(spec, variant, env, template, keys, train_batch, test_batch):
    """(returns (trials × test contexts), curve steps, curves (trials × points), per-trial params)."""
    function = _compiled(spec, variant, env, template)
    returns, steps, curves, params = function(keys, train_batch, test_batch)
    params = jax.device_get(params)
    per_trial = [
        None if params is None else jax.tree_util.tree_map(lambda leaf, i=i: leaf[i], params)
        for i in range(len(keys))
    ]
    return np.asarray(returns), np.asarray(steps[0]), np.asarray(curves), per_trial


def _like(contexts, template):
    """A one-context set repeated to the template's size (a specialist seeing the template's features)."""
    if len(contexts) == len(template):
        return contexts
    if len(contexts) != 1:
        raise ValueError(
            f"cannot shape a set of {len(contexts)} contexts like one of {len(template)}"
        )
    return jax.tree_util.tree_map(lambda leaf: jax.numpy.repeat(leaf, len(template), 0), contexts)


def run_chunk(plan: Plan, chunk: list[int]) -> ChunkResult:
    """Train and evaluate the trials ``chunk`` (indices into ``plan.trials``) together."""
    start = time.perf_counter()
    spec = plan.spec
    trials = [plan.trials[i] for i in chunk]
    env = spec.make_env()
    template = plan.sets[trials[0].template].contexts
    keys = jax.numpy.stack([trial_key(spec.seed, t.id) for t in trials])
    train_batch = stack_sets([_like(plan.sets[t.train_set].contexts, template) for t in trials])
    test_batch = stack_sets([plan.sets[t.test_set].contexts for t in trials])
    returns, steps, curves, params = _train_and_evaluate(
        spec, trials[0].variant, env, template, keys, train_batch, test_batch
    )
    seconds = time.perf_counter() - start
    space = env.context_space
    eval_frames, curve_frames = [], []
    for row, trial in enumerate(trials):
        test = plan.sets[trial.test_set]
        frame = pd.DataFrame(
            {
                "trial": trial.id,
                "kind": trial.kind,
                "variant": trial.variant,
                "seed": trial.seed,
                "train_set": trial.train_set,
                "test_set": trial.test_set,
                "context_index": np.arange(len(test)),
                **{f"ctx.{n}": np.asarray(getattr(test.contexts, n)) for n in space.names},
                **{k: list(v) for k, v in test.labels.items()},
                "return": returns[row].astype(np.float64),
                "chunk_seconds": seconds,
            }
        )
        eval_frames.append(frame)
        if steps.size:
            curve_frames.append(
                pd.DataFrame(
                    {
                        "trial": trial.id,
                        "kind": trial.kind,
                        "variant": trial.variant,
                        "seed": trial.seed,
                        "step": steps.astype(np.int64),
                        "episode_return": curves[row].astype(np.float64),
                    }
                )
            )
    curves_frame = pd.concat(curve_frames, ignore_index=True) if curve_frames else pd.DataFrame()
    return ChunkResult(pd.concat(eval_frames, ignore_index=True), curves_frame, params, seconds)
