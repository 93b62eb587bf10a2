"""The environment core: Env, TimeStep, spaces, the registry, context-scheduled environments and the
return's gradient with respect to the context."""

from contextrl.core.contextual import (
    ContextualEnv,
    ContextualState,
    choose_context,
    make_provider,
    with_contexts,
)
from contextrl.core.env import Env, EnvState, TimeStep, checked, tree_where
from contextrl.core.gradient import context_gradient, return_of_context
from contextrl.core.host import HostEnv
from contextrl.core.registry import EnvSpec, make, register, registered, spec
from contextrl.core.spaces import Box, Discrete

__all__ = [
    "Box",
    "ContextualEnv",
    "ContextualState",
    "Discrete",
    "checked",
    "choose_context",
    "context_gradient",
    "Env",
    "EnvSpec",
    "EnvState",
    "HostEnv",
    "TimeStep",
    "make",
    "make_provider",
    "register",
    "registered",
    "return_of_context",
    "spec",
    "tree_where",
    "with_contexts",
]
