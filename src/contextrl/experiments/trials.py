"""Run one chunk of trials: every trial of the chunk trains and is evaluated in one vmapped call.

Agents come from the agent registry (:mod:`contextrl.agents.registry`), so any registered agent runs in
every protocol; an untrained agent (the random baseline) only evaluates. Each trial is also evaluated
on (up to ``TRAIN_EVAL_CONTEXTS`` of) its own training contexts next to a uniform random policy, so a
report can say whether the agents learned at all. A chunk returns plain tables, so it can run in this
process or on a Ray worker.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import jax
import numpy as np
import pandas as pd

from contextrl.agents import evaluate, get_agent
from contextrl.agents.host import HostCollector
from contextrl.agents.networks import ContextInput, context_input
from contextrl.core.gradient import differentiated, return_of_context
from contextrl.experiments.plan import Plan, context_columns, stack_sets, trial_columns, trial_key

TRAIN_EVAL_CONTEXTS = 16
GRADIENT_STEP = 0.01  # the central difference beside each gradient: A = 1 ± 0.01


@dataclasses.dataclass
class ChunkResult:
    """Evaluation rows (one per trial × test context), training-curve rows, per-trial returns on the
    training contexts (trained and random policy), trained parameters, and what a checkpoint needs to
    rebuild the policy (config, training contexts, agent and environment names)."""

    evaluations: pd.DataFrame
    curves: pd.DataFrame
    params: list[Any]
    seconds: float
    training: pd.DataFrame = dataclasses.field(default_factory=pd.DataFrame)
    checkpoint: dict = dataclasses.field(default_factory=dict)


_COMPILED: dict[tuple, Any] = {}


def _first(contexts, n: int):
    return jax.tree_util.tree_map(lambda leaf: leaf[:n], contexts)


def _compiled(spec, variant: str, env, template, tested_on_training: bool, curriculum: str):
    """The jitted, vmapped train-and-evaluate function; chunks of the same shape share one compile.

    Only the structure of ``template`` matters (its size and which features vary), so it is the key.
    ``tested_on_training``: the test set is the training set (optimality gap), so the trained
    policy's return there is read from the test returns instead of evaluated twice. ``curriculum``:
    the agent trains under the spec's curriculum of that name over the template (its pool), which
    chooses the training contexts itself; its distribution per update comes back with the curve.
    """
    agent = spec.agent_entry()
    key = (
        spec.env,
        spec.max_steps,
        spec.agent,
        repr(sorted(spec.agent_options.items())),
        spec.eval_episodes,
        variant if agent.trained else "",  # an untrained policy ignores the context input
        tested_on_training,
        spec.gradient_features(env),
        len(template),
        env.context_space.varying(template) if len(template) > 1 else (),
        # a curriculum holds its pool and options: the spec that makes them keys it
        (curriculum, repr(spec)) if curriculum else (),
    )
    if key in _COMPILED:
        return _COMPILED[key]
    episodes = spec.eval_episodes
    config = spec.agent_config(variant)
    policy = agent.make_policy(config, env, template)
    random_policy = get_agent("random").make_policy(None, env, template)
    taught = spec.make_curriculum(curriculum, template) if curriculum else None
    train = agent.make_train(config, env, taught or template) if agent.trained else None
    names = spec.gradient_features(env) if agent.trained else ()
    slopes = _slopes(env, policy, names, episodes) if names else None

    def one(key, train_ctx, test_ctx):
        train_key, eval_key, train_eval_key = jax.random.split(key, 3)
        trace = {}
        if train is None:
            params, steps, curve = None, jax.numpy.zeros(0), jax.numpy.zeros(0)
        else:
            result = train(train_key) if taught else train(train_key, train_ctx)
            params, steps = result.params, result.metrics["step"]
            curve = result.metrics["episode_return"]
            trace = result.metrics.get("curriculum", {})
        returns = evaluate(policy, params, env, test_ctx, episodes, eval_key)
        own = _first(train_ctx, TRAIN_EVAL_CONTEXTS)
        if tested_on_training:
            trained = returns[:TRAIN_EVAL_CONTEXTS].mean()
        else:
            trained = evaluate(policy, params, env, own, episodes, train_eval_key).mean()
        random = evaluate(random_policy, None, env, own, episodes, train_eval_key).mean()
        slope = {} if slopes is None else slopes(params, jax.random.fold_in(eval_key, 1))
        return returns, steps, curve, params, trained, random, trace, slope

    _COMPILED[key] = jax.jit(jax.vmap(one))
    return _COMPILED[key]


def _slopes(env, policy, names, episodes):
    """``(params, key) -> {column: value}``: per feature in ``names``, the derivative of the mean
    return over ``episodes`` episodes with respect to its magnitude A (feature = A × default) at the
    default context, from one differentiated pass (``gradient.NAME``; the mode
    ``contextrl.core.gradient.differentiated`` chooses), and the central difference at
    A = 1 ± ``GRADIENT_STEP`` over the same episodes and draws (``difference.NAME``)."""
    default = env.context_space.default()
    scale = {name: float(getattr(default, name)) for name in names}

    def slopes(params, key):
        keys = jax.random.split(key, episodes)

        def mean_return(magnitudes):
            def episode(episode_key):
                return_of, _ = return_of_context(
                    env,
                    policy,
                    default,
                    key=episode_key,
                    horizon=env.max_steps,
                    features=names,
                    params=params,
                )
                return return_of({n: magnitudes[n] * scale[n] for n in names})

            return jax.vmap(episode)(keys).mean()

        ones = {name: jax.numpy.float32(1.0) for name in names}
        gradient = differentiated(env, mean_return)(ones)
        # every feature at 1 + step, then every one at 1 - step: one vmapped rollout for all
        moved = np.concatenate([np.eye(len(names)), -np.eye(len(names))]) * GRADIENT_STEP + 1.0
        returns = jax.vmap(mean_return)({n: moved[:, i] for i, n in enumerate(names)})
        columns = {}
        for i, name in enumerate(names):
            up, down = returns[i], returns[len(names) + i]
            columns[f"gradient.{name}"] = gradient[name]
            columns[f"difference.{name}"] = (up - down) / (2 * GRADIENT_STEP)
        return columns

    return slopes


def _train_and_evaluate(spec, trials, env, template, keys, train_batch, test_batch, same):
    """(returns (trials × test contexts), curve steps, curves (trials × points), per-trial params,
    per-trial (trained, random) mean return on the training contexts, the curriculum's columns of
    the curves: name → trials × points, the return's slopes in the context: column → trials)."""
    first = trials[0]
    function = _compiled(spec, first.variant, env, template, same, first.curriculum)
    outputs = function(keys, train_batch, test_batch)
    returns, steps, curves, params, trained, random, trace, slopes = outputs
    params = jax.device_get(params)
    per_trial = [
        None if params is None else jax.tree_util.tree_map(lambda leaf, i=i: leaf[i], params)
        for i in range(len(keys))
    ]
    own = np.stack([np.asarray(trained), np.asarray(random)], axis=1)
    return (
        np.asarray(returns),
        np.asarray(steps[0]),
        np.asarray(curves),
        per_trial,
        own,
        curriculum_columns(trace),
        {column: np.asarray(values, np.float64) for column, values in slopes.items()},
    )


def curriculum_columns(trace: dict) -> dict[str, np.ndarray]:
    """A curriculum's per-update arrays (trials × updates × …) as curve columns: ``curriculum.NAME``
    for one number per update, ``curriculum.NAME.I`` for entry I of a vector (a pool's weights)."""
    columns = {}
    for name, values in trace.items():
        values = np.asarray(values, np.float64)
        if values.ndim == 2:
            columns[f"curriculum.{name}"] = values
        else:
            for index in range(values.shape[2]):
                columns[f"curriculum.{name}.{index}"] = values[:, :, index]
    return columns


def host_context_input(spec, variant: str, env, template):
    """What a host-trained agent of ``variant`` sees of the context (nothing for an untrained one)."""
    trained = spec.agent_entry().trained
    return (context_input(variant, env.context_space, template) if trained else None) or (
        ContextInput()
    )


def host_returns(spec, context, policy, params, contexts, episodes: int, key) -> np.ndarray:
    """Mean return per context of a host policy, one host copy per context."""
    limit = {} if spec.max_steps is None else {"max_steps": spec.max_steps}
    seed = int(jax.random.randint(key, (), 0, 2**31 - 1))
    with HostCollector(
        spec.env,
        len(contexts),
        contexts,
        selector="round_robin",  # copy i runs context i
        seed=seed,
        context=context,
        **limit,
    ) as collector:
        return collector.evaluate(policy, params, episodes, key)


def _host_train_and_evaluate(plan: Plan, trials, env, template, keys):
    """The host path of a chunk: each trial trains on the shared host collector (the agent's
    ``train_host``), then acts in host copies of its test and training contexts; same outputs as
    :func:`_train_and_evaluate`."""
    spec = plan.spec
    agent = spec.agent_entry()
    variant = trials[0].variant
    config = spec.agent_config(variant)
    context = host_context_input(spec, variant, env, template)
    act = jax.jit(agent.make_policy(config, env, template).act)
    random_act = jax.jit(get_agent("random").make_policy(None, env, template).act)
    limit = {} if spec.max_steps is None else {"max_steps": spec.max_steps}

    def evaluate(policy, params, contexts, key) -> np.ndarray:
        return host_returns(spec, context, policy, params, contexts, spec.eval_episodes, key)

    returns, steps, curves, params, own = [], np.zeros(0), [], [], []
    for trial, key in zip(trials, keys, strict=True):
        train_key, eval_key, own_key = jax.random.split(key, 3)
        train_set = plan.sets[trial.train_set].contexts
        trial_params = None
        if agent.trained:
            seed = int(jax.random.randint(train_key, (), 0, 2**31 - 1))
            result = agent.train_host(
                config, spec.env, train_set, train_key, seed=seed, context=context, **limit
            )
            trial_params, steps = result.params, np.asarray(result.metrics["step"])
            curves.append(np.asarray(result.metrics["episode_return"]))
        returns.append(evaluate(act, trial_params, plan.sets[trial.test_set].contexts, eval_key))
        mine = _first(train_set, TRAIN_EVAL_CONTEXTS)
        own.append(
            (
                evaluate(act, trial_params, mine, own_key).mean(),
                evaluate(random_act, None, mine, own_key).mean(),
            )
        )
        params.append(trial_params)
    return np.stack(returns), steps, np.asarray(curves), params, np.asarray(own), {}, {}


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
    if spec.host:
        returns, steps, curves, params, own, taught, slopes = _host_train_and_evaluate(
            plan, trials, env, template, keys
        )
    else:
        train_batch = stack_sets([_like(plan.sets[t.train_set].contexts, template) for t in trials])
        test_batch = stack_sets([plan.sets[t.test_set].contexts for t in trials])
        same = all(t.test_set == t.train_set for t in trials)
        returns, steps, curves, params, own, taught, slopes = _train_and_evaluate(
            spec, trials, env, template, keys, train_batch, test_batch, same
        )
    seconds = time.perf_counter() - start
    space = env.context_space
    eval_frames, curve_frames = [], []
    for row, trial in enumerate(trials):
        test = plan.sets[trial.test_set]
        frame = pd.DataFrame(
            {
                **trial_columns(trial),
                **context_columns(test, space.names),
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
                        **{name: values[row] for name, values in taught.items()},
                    }
                )
            )
    curves_frame = pd.concat(curve_frames, ignore_index=True) if curve_frames else pd.DataFrame()
    training = pd.DataFrame(
        {
            "trial": [t.id for t in trials],
            "kind": [t.kind for t in trials],
            "variant": [t.variant for t in trials],
            "seed": [t.seed for t in trials],
            "train_return": own[:, 0].astype(np.float64),
            "random_return": own[:, 1].astype(np.float64),
            **slopes,
        }
    )
    checkpoint = {
        "config": spec.agent_config(trials[0].variant),
        "train_contexts": template,
        "agent": spec.agent,
        "env": spec.env,
        "max_steps": spec.max_steps,
        **spec.env_options,
    }
    return ChunkResult(
        pd.concat(eval_frames, ignore_index=True),
        curves_frame,
        params,
        seconds,
        training,
        checkpoint,
    )
