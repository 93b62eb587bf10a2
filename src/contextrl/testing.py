"""A public environment checker: ``check_env(env)`` proves a JAX environment keeps the library's promises.

It compiles reset and step, vmaps them over contexts drawn across the whole declared bounds, checks that
changing context values never recompiles, that the same key gives the same trajectory, that observations
stay inside the observation space and that the time limit truncates. Above all it checks, feature by
feature, that every declared effect is real and every effect is declared: a feature that says it changes
the dynamics must change the next state, one that does not say so must leave it alone (the CARL failure
mode is a feature that silently does nothing).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import Feature
from contextrl.core.env import Env


def contexts_across_bounds(env: Env, n: int, key) -> object:
    """``n`` contexts with every feature drawn uniformly over its whole declared range."""
    values = {}
    for index, (name, f) in enumerate(env.context_space.features.items()):
        k = jax.random.fold_in(key, index)
        if f.kind == "float":
            values[name] = jax.random.uniform(k, (n,), minval=f.lower, maxval=f.upper)
        else:
            values[name] = jax.random.randint(k, (n,), int(f.lower), int(f.upper) + 1)
    return env.context_space.context_class(**values)


def default_and_random_contexts(env: Env, n: int, key) -> object:
    """A batch of ``n`` contexts: the default first, the rest drawn across the bounds."""
    default = env.context_space.stack([env.default_context()])
    if n == 1:
        return default
    rest = contexts_across_bounds(env, n - 1, key)
    return jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), default, rest)


def probe_values(f: Feature) -> list[float]:
    """Values that differ from the default: both bounds and the midpoints towards them."""
    if f.kind == "categorical":
        return [i for i in range(len(f.choices)) if i != f.default]
    candidates = [f.lower, f.upper, (f.lower + f.default) / 2, (f.upper + f.default) / 2]
    if f.kind == "int":
        candidates = [round(c) for c in candidates]
    return sorted({c for c in candidates if c != f.default})


# Float values differ when they differ beyond rounding. Two separately compiled copies of a step
# round differently (under ``--xla_backend_optimization_level=0``, Acrobot's next states differed in
# the last bit for features its step never reads), so the base and the changed context go through one
# vmapped computation (``_effects``); the margin covers code that rounds differently per vector lane.
RTOL, ATOL = 1e-5, 1e-6


def _leaf_differs(x, y) -> jax.Array:
    if not jnp.issubdtype(jnp.result_type(x), jnp.inexact):
        return jnp.any(x != y)
    apart = jnp.abs(x - y) > ATOL + RTOL * jnp.abs(y)
    return jnp.any(apart & jnp.isfinite(x) & jnp.isfinite(y))


def _finite(tree) -> jax.Array:
    """Whether every float in a pytree is finite."""
    leaves = jax.tree_util.tree_leaves(tree)
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(leaf)) for leaf in leaves]))


def _differs(a, b) -> jax.Array:
    """Whether two pytrees differ anywhere both are finite (diverged physics is not an effect) by
    more than rounding (``RTOL``, ``ATOL``)."""
    leaves = jax.tree_util.tree_leaves(jax.tree_util.tree_map(_leaf_differs, a, b))
    return jnp.any(jnp.stack(leaves))


def _effects(env: Env, steps: int):
    """A function (base, changed, key) → which effects a change of context showed along a trajectory.

    The trajectory follows the base context with random actions, going back to its own start when an
    episode ends (a fresh start at every step would put the start's search, a collision pass for
    Quadruped and a rejection loop for Finger, inside the scanned body); at every state the changed
    context's transition, reward, termination and observation are compared with the base's.
    Both contexts go through one vmapped computation, the same compiled code: two separately compiled
    copies of a step can round differently, and a solver that iterates to a tolerance (MJX's) can turn
    that into differences far beyond rounding.
    """

    def both(function, *args):
        """``function(*args, context)`` for the base and the changed context at once (leading axis)."""
        return lambda base, changed: jax.vmap(lambda context: function(*args, context))(
            jax.tree_util.tree_map(lambda b, c: jnp.stack([b, c]), base, changed)
        )

    def pick(tree, index):
        return jax.tree_util.tree_map(lambda leaf: leaf[index], tree)

    def effects(base, changed, key):
        start_key, run_key = jax.random.split(key)
        starts = both(env.init, start_key)(base, changed)
        start = pick(starts, 0)

        def body(state, step_key):
            action_key, transition_key = jax.random.split(step_key)
            action = env.action_space.sample(action_key)
            nexts, rewards, terms = both(env.transition, transition_key, state, action)(
                base, changed
            )
            observations = both(env.observe, state)(base, changed)
            finite = [
                _finite((env.state_variables(pick(nexts, i)), rewards[i], observations[i]))
                for i in (0, 1)
            ]
            shown = jnp.stack(
                [
                    _differs(
                        env.state_variables(pick(nexts, 0)), env.state_variables(pick(nexts, 1))
                    ),
                    _differs(rewards[0], rewards[1]),
                    terms[0] != terms[1],
                    _differs(observations[0], observations[1]),
                    finite[0] & ~finite[1],  # the changed value alone broke the physics
                ]
            )
            state = jax.tree_util.tree_map(
                lambda r, s: jnp.where(terms[0], r, s), start, pick(nexts, 0)
            )
            return state, shown

        _, shown = jax.lax.scan(body, start, jax.random.split(run_key, steps))
        dynamics, reward, termination, observation, diverged = jnp.any(shown, axis=0)
        return {
            "diverged": diverged,
            "start_state": _differs(
                env.state_variables(start), env.state_variables(pick(starts, 1))
            ),
            "dynamics": dynamics,
            "reward": reward,
            "termination": termination,
            "observation": observation,
        }

    return effects


def check_feature_effects(
    env: Env,
    key,
    *,
    num_bases: int = 4,
    num_keys: int = 4,
    steps: int = 200,
    bases: object | None = None,
) -> dict[str, dict[str, bool]]:
    """Per feature, which effects were observed; raises AssertionError on a missing or undeclared one,
    or on a value inside the feature's bounds that gives non-finite states, rewards or observations.

    Each feature is moved to its bounds and midpoints, from the default context and from random ones
    (and from ``bases``, a batch of contexts, where given: a goal that random actions never reach
    shows its effect from a context that starts at it), and compared with the unchanged context along
    the same random trajectories.
    """
    space = env.context_space
    steps = min(steps, env.max_steps)
    bases_key, key = jax.random.split(key)
    drawn = default_and_random_contexts(env, num_bases, bases_key)
    if bases is not None:
        drawn = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), drawn, bases)
    bases, num_bases = drawn, len(jax.tree_util.tree_leaves(drawn)[0])
    effects = jax.jit(jax.vmap(_effects(env, steps)))
    keys = jax.random.split(key, num_keys)
    observed, problems = {}, []
    # Every feature's batch is padded (by repeating its pairs) to one size, so ``effects`` compiles once.
    size = num_bases * num_keys * max(len(probe_values(f)) for f in space.features.values())
    for name, f in space.features.items():
        probes = probe_values(f)
        pairs = [(b, p, k) for b in range(num_bases) for p in probes for k in range(num_keys)]
        pairs = [pairs[i % len(pairs)] for i in range(size)]
        base_index = np.array([b for b, _, _ in pairs])
        base = bases[base_index]
        changed_values = jnp.asarray(np.array([p for _, p, _ in pairs]), f.dtype)
        changed = dataclasses.replace(base, **{name: changed_values})
        shown = effects(base, changed, keys[np.array([k for _, _, k in pairs])])
        diverged = sorted({pairs[i][1] for i in np.flatnonzero(np.asarray(shown.pop("diverged")))})
        if diverged:
            problems.append(
                f"{name} = {', '.join(map(str, diverged))} (inside its bounds [{f.lower}, "
                f"{f.upper}]) gave non-finite states, rewards or observations"
            )
        shown = {effect: bool(np.any(v)) for effect, v in shown.items()}
        observed[name] = shown
        declared = set(f.affects)
        expectations = {
            "start_state": shown["start_state"],
            "dynamics": shown["dynamics"],
            "reward": shown["reward"],
            "goal": shown["termination"] or shown["reward"],
            "observation": shown["observation"],
        }
        for effect in declared:
            if not expectations[effect]:
                problems.append(f"{name}: declared to affect {effect}, but changing it did not")
        if "dynamics" not in declared and shown["dynamics"]:
            problems.append(f"{name}: changes the dynamics but does not declare it")
        if "start_state" not in declared and shown["start_state"]:
            problems.append(f"{name}: changes the start state but does not declare it")
        # A dynamics feature moves the next state, which the reward and termination then read.
        undeclared = not declared & {"reward", "goal", "dynamics"}
        if undeclared and (shown["reward"] or shown["termination"]):
            problems.append(f"{name}: changes reward or termination but declares neither")
        if "observation" not in declared and shown["observation"]:
            problems.append(f"{name}: changes the observation but does not declare it")
    if problems:
        raise AssertionError(f"{env.name}: " + "; ".join(problems))
    return observed


def _rollout(env: Env, steps: int):
    """A pure function (key, contexts) → per-step TimeSteps and episode clocks of a batched rollout."""

    def rollout(key, contexts):
        n = len(contexts)
        reset_key, run_key = jax.random.split(key)
        state, first = jax.vmap(env.reset)(jax.random.split(reset_key, n), contexts)

        def body(state, step_key):
            action_key, env_key = jax.random.split(step_key)
            actions = jax.vmap(env.action_space.sample)(jax.random.split(action_key, n))
            next_state, ts = jax.vmap(env.step)(
                jax.random.split(env_key, n), state, actions, contexts
            )
            return next_state, (ts, state.time + 1, next_state.time)

        _, (timesteps, clock, next_clock) = jax.lax.scan(
            body, state, jax.random.split(run_key, steps)
        )
        return first, timesteps, clock, next_clock

    return rollout


def check_env(
    env: Env,
    key=None,
    *,
    num_contexts: int = 8,
    steps: int | None = None,
    effect_steps: int = 200,
    effect_bases: object | None = None,
) -> None:
    """Run every check on a JAX environment; raises AssertionError with what went wrong.

    ``steps`` is the rollout's length (default: past the time limit), ``effect_steps`` how long each
    feature's effect is looked for and ``effect_bases`` extra contexts it is looked for from
    (:func:`check_feature_effects`)."""
    key = jax.random.key(0) if key is None else key
    steps = env.max_steps + 5 if steps is None else steps
    contexts_key, rollout_key, effects_key = jax.random.split(key, 3)
    space = env.context_space
    space.check(env.default_context())
    contexts = default_and_random_contexts(env, num_contexts, contexts_key)

    # Compiles once: a second call with other context values must reuse the compiled rollout.
    traces = []

    def traced(key, contexts):
        traces.append(1)
        return _rollout(env, steps)(key, contexts)

    rollout = jax.jit(traced)
    first, timesteps, clock, next_clock = rollout(rollout_key, contexts)
    other = contexts_across_bounds(env, num_contexts, jax.random.fold_in(contexts_key, 1))
    rollout(rollout_key, other)
    assert len(traces) == 1, f"{env.name}: changing context values recompiled the rollout"

    # Same key, same trajectory; a different key, a different one.
    again = rollout(rollout_key, contexts)
    same = jax.tree_util.tree_map(lambda a, b: np.array_equal(a, b), timesteps, again[1])
    assert all(jax.tree_util.tree_leaves(same)), f"{env.name}: same key gave another trajectory"
    different = rollout(jax.random.fold_in(rollout_key, 1), contexts)
    assert not np.array_equal(timesteps.obs, different[1].obs), (
        f"{env.name}: a different key gave the same trajectory"
    )

    # Observations inside the space, everything finite, at contexts across the whole bounds.
    obs_space = env.observation_space
    for name, batch in (
        ("reset", first.obs),
        ("step", timesteps.obs),
        ("final", timesteps.final_obs),
    ):
        array = np.asarray(batch).reshape(-1, *obs_space.shape)
        assert np.all(np.isfinite(array)), f"{env.name}: non-finite {name} observation"
        inside = (array >= obs_space.low) & (array <= obs_space.high)
        assert np.all(inside), f"{env.name}: {name} observation outside the observation space"
    assert np.all(np.isfinite(np.asarray(timesteps.reward))), f"{env.name}: non-finite reward"
    for dtype_check, what in (
        (np.asarray(timesteps.terminated).dtype == bool, "terminated"),
        (np.asarray(timesteps.truncated).dtype == bool, "truncated"),
    ):
        assert dtype_check, f"{env.name}: {what} is not boolean"

    # The time limit truncates exactly at max_steps, and an ended episode restarts at once.
    clock, next_clock = np.asarray(clock), np.asarray(next_clock)
    truncated = np.asarray(timesteps.truncated)
    done = truncated | np.asarray(timesteps.terminated)
    assert np.array_equal(truncated, clock >= env.max_steps), f"{env.name}: wrong truncation"
    assert np.all(next_clock[done] == 0) and np.all(next_clock[~done] == clock[~done]), (
        f"{env.name}: an ended episode did not restart in the same step"
    )
    ended = done.reshape(-1)
    if ended.any():
        obs = np.asarray(timesteps.obs).reshape(-1, *obs_space.shape)
        final = np.asarray(timesteps.final_obs).reshape(-1, *obs_space.shape)
        assert np.array_equal(obs[~ended], final[~ended]), (
            f"{env.name}: final_obs != obs mid-episode"
        )

    # Actions: the space's samples are accepted under jit and vmap (checked above); spaces convert.
    env.action_space.to_gymnasium()
    obs_space.to_gymnasium()

    check_feature_effects(env, effects_key, steps=effect_steps, bases=effect_bases)
