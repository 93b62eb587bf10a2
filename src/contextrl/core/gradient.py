"""The return's gradient with respect to the context, from one differentiated rollout.

For a JAX environment whose dynamics are differentiable (``Env.differentiable``), one rollout of a
fixed number of steps under a fixed key carries the derivative of a policy's return with respect to each
float context feature, where a sweep needs a grid of rollouts. Where the environment never
terminates it runs in reverse mode (``jax.grad``, one backward pass through the scan); where it can
terminate, in forward mode (``jax.jacfwd``, one tangent per feature), since the backward pass would go
through the terminating step's fraction at every step: measured in
``benchmarks/bench_context_gradient.py``.

A termination is a jump: an episode that lasts one step longer collects one more reward, so CartPole's
return is a step function of its context whose derivative is zero almost everywhere. The rollout
counts the step in which the episode terminates by the fraction of it spent before the environment's
``termination_margin`` crosses zero (interpolated linearly between the states before and after the
step), and nothing after it. The return is then continuous in the context where a terminating step
earns what a step that goes on earns (CartPole's +1), and its derivative is that of how long the
episode lasts. Where the terminating step earns more, a goal's reward (Acrobot's 0 against −1 a step,
MountainCarContinuous's +100), the environment's ``termination_bonus(context)`` names the excess: it
counts in full and only the rest by the fraction. A discrete policy's actions have no derivative: the
gradient holds them where they are, which is the return's derivative between the contexts at which an
action switches.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import ContextError
from contextrl.core.env import Env
from contextrl.core.host import HostEnv


def context_gradient(
    env: Env,
    policy: Callable[[jax.Array], Any],
    context: Any,
    *,
    key: jax.Array,
    horizon: int,
    features: Sequence[str] | None = None,
    params: Any = None,
) -> dict[str, float]:
    """d(return)/d(feature) at ``context`` for each float feature (or those in ``features``).

    ``policy`` maps an observation to an action; it acts for ``horizon`` steps (at most the time limit)
    of one episode started by ``env.reset`` under ``key``, the steps drawing from keys split from it.
    With ``params``, it is a trained agent's policy called as the agents' policies are,
    ``policy(params, obs, context, key)``: a policy that sees the context is differentiated through
    its context input too.
    """
    return_of, values = return_of_context(
        env, policy, context, key=key, horizon=horizon, features=features, params=params
    )
    gradient = jax.jit(differentiated(env, return_of))(values)
    return {name: float(gradient[name]) for name in values}


def differentiated(env: Env, return_of: Callable) -> Callable:
    """The derivative of :func:`return_of_context`'s function as :func:`context_gradient` takes it:
    reverse mode for an environment that never terminates, forward mode for one that can."""
    return jax.grad(return_of) if never_terminates(env) else jax.jacfwd(return_of)


def never_terminates(env: Env) -> bool:
    """Whether ``env`` declares no termination (it keeps ``Env.termination_margin``'s None)."""
    return type(env).termination_margin is Env.termination_margin


def return_of_context(
    env: Env,
    policy: Callable[[jax.Array], Any],
    context: Any,
    *,
    key: jax.Array,
    horizon: int,
    features: Sequence[str] | None = None,
    params: Any = None,
) -> tuple[Callable[[dict[str, jax.Array]], jax.Array], dict[str, jax.Array]]:
    """The return :func:`context_gradient` differentiates, as a pure function of a dict of the float
    features' values (the others stay at ``context``'s), and that dict at ``context``: to compile,
    differentiate or ``vmap`` over many values."""
    context, names = _checked(env, policy, context, key, horizon, features)
    reset_key, steps_key = jax.random.split(key)

    def return_of(values):
        ctx = dataclasses.replace(
            context, **{name: jnp.asarray(values[name], jnp.float32) for name in names}
        )
        state, start = env.reset(reset_key, ctx)

        def step(carry, step_key):
            state, obs, alive, total = carry
            before = env.termination_margin(state.physics, ctx)
            if params is None:
                action = policy(obs)
            else:
                step_key, action_key = jax.random.split(step_key)
                action = policy(params, obs, ctx, action_key)
            state, ts = env.advance(step_key, state, action, ctx)
            reward = ts.reward
            if before is not None:  # the step that ends the episode counts by its part inside
                ending = ts.terminated & (alive > 0)
                crossed = jnp.where(
                    ending, before - env.termination_margin(state.physics, ctx), 1.0
                )
                part = jnp.where(ending, jnp.clip(before / crossed, 0.0, 1.0), 1.0)
                bonus = jnp.where(ending, env.termination_bonus(ctx), 0.0)
                reward = part * (reward - bonus) + bonus
            total = total + alive * reward
            alive = alive * (1.0 - ts.terminated)
            return (state, ts.obs, alive, total), None

        carry = (state, start.obs, jnp.float32(1.0), jnp.float32(0.0))
        (_, _, _, total), _ = jax.lax.scan(step, carry, jax.random.split(steps_key, horizon))
        return total

    return return_of, {name: getattr(context, name) for name in names}


def _differentiable_names() -> list[str]:
    """The loaded environment classes that declare differentiable dynamics; one whose declaration is
    a property (it holds on some backends only, like Brax Reacher's on MJX) is named as such."""
    found, pending = set(), [Env]
    while pending:
        cls = pending.pop()
        pending.extend(cls.__subclasses__())
        declared = cls.__dict__.get("differentiable")
        if declared is True:
            found.add(cls.__name__)
        elif isinstance(declared, property):
            found.add(f"{cls.__name__} (on some backends)")
    return sorted(found)


def _checked(env, policy, context, key, horizon, features):
    """The validated context and feature names; every refusal is one line, before anything runs."""
    valid = f"differentiable environments: {', '.join(_differentiable_names())}"
    if isinstance(env, HostEnv):
        raise ValueError(
            f"context_gradient: {env.name} is a host environment (its simulator steps on the CPU, "
            f"outside JAX), so its return has no JAX gradient; {valid}"
        )
    if not isinstance(env, Env):
        raise TypeError(f"context_gradient: expected a contextrl Env, got {type(env).__name__}")
    if not env.differentiable:
        raise ValueError(
            f"context_gradient: {env.name}'s dynamics are not declared differentiable in its "
            f"context (Env.differentiable); {valid}"
        )
    if not callable(policy):
        raise TypeError(
            f"context_gradient: policy must be a function obs -> action, got {type(policy).__name__}"
        )
    context = env.as_context(context)
    env.check_context(context)
    if context.batch_shape:
        raise ContextError(
            f"context_gradient: one context of {env.name}, got a batch of shape "
            f"{context.batch_shape}; index it (contexts[i]) for one"
        )
    _check_key(key)
    if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)):
        raise ValueError(f"context_gradient: horizon must be an integer, got {horizon!r}")
    if not 1 <= horizon <= env.max_steps:
        raise ValueError(
            f"context_gradient: horizon must be in [1, {env.max_steps}] ({env.name}'s time limit), "
            f"got {horizon}"
        )
    return context, _float_features(env, features)


def _check_key(key) -> None:
    dtype = getattr(key, "dtype", None)
    typed = dtype is not None and jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key)
    if typed and key.shape == ():
        return
    if not typed and dtype == np.uint32 and key.shape == (2,):
        return
    shape = getattr(key, "shape", None)
    raise ValueError(
        f"context_gradient: key must be one JAX key (jax.random.key(seed)), got "
        f"{type(key).__name__} of shape {shape}"
    )


def _float_features(env, features) -> tuple[str, ...]:
    """The canonical names to differentiate: every float feature, or the named ones (all float)."""
    space = env.context_space
    floats = [name for name, f in space.features.items() if f.kind == "float"]
    if features is None:
        if not floats:
            raise ContextError(f"context_gradient: {env.name} has no float context feature")
        return tuple(floats)
    if isinstance(features, str):
        raise ContextError(
            f"context_gradient: features is a list of names, got the string {features!r}"
        )
    names = []
    for given in features:
        name = space.resolve(given)
        kind = space.features[name].kind
        if kind != "float":
            raise ContextError(
                f"context_gradient: {env.name}'s feature {name} is {kind}, which has no gradient; "
                f"float features: {floats}"
            )
        if name in names:
            raise ContextError(f"context_gradient: feature {name} given twice")
        names.append(name)
    if not names:
        raise ContextError(f"context_gradient: features is empty; float features: {floats}")
    return tuple(names)
