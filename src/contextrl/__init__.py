"""contextrl: contextual reinforcement learning with explicit, named, bounded contexts.

import jax, contextrl as crl
env = crl.make("CartPole")
contexts = crl.sample(env, {"length": crl.Uniform(0.25, 0.75)}, n=4096, key=jax.random.key(0))
state, ts = jax.vmap(env.reset)(keys, contexts)
"""

from contextrl import envs as _envs  # noqa: F401  (registers the environments)
from contextrl.context import (
    Categorical,
    Constant,
    ContextError,
    LogUniform,
    Normal,
    Piecewise,
    RandomWalk,
    Redraw,
    RelativeUniform,
    Scaled,
    StepFunction,
    Uniform,
    context_type,
    feature,
    sample,
)
from contextrl.core import (
    ContextualEnv,
    Env,
    TimeStep,
    checked,
    context_gradient,
    make,
    register,
    registered,
    return_of_context,
    spec,
    with_contexts,
)
from contextrl.gymnasium import register_envs as _register_gymnasium_ids

_register_gymnasium_ids()  # every id above, also as gymnasium's contextrl/<Id>-v0

__version__ = "0.1.0"

__all__ = [
    "Categorical",
    "Constant",
    "ContextError",
    "ContextualEnv",
    "Env",
    "LogUniform",
    "Normal",
    "Piecewise",
    "RandomWalk",
    "Redraw",
    "RelativeUniform",
    "Scaled",
    "StepFunction",
    "TimeStep",
    "Uniform",
    "checked",
    "context_gradient",
    "context_type",
    "feature",
    "make",
    "register",
    "registered",
    "return_of_context",
    "sample",
    "spec",
    "with_contexts",
]
