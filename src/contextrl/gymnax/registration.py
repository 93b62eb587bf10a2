"""gymnax 1.0's registry: ``register(id, factory)`` adds a user's own environment to ``make``.

``_registry`` and ``registered_envs`` are looked up at every call, as gymnax's are, so a test can swap
them for copies; ``contextrl.gymnax.v1`` registers contextrl's JAX environments here at import.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

_registry: dict[str, Callable[..., Any]] = {}
registered_envs: list[str] = []


def register(env_id: str, factory: Callable[..., Any]) -> None:
    """Let ``make(env_id, **kwargs)`` return ``factory(**kwargs)`` (a new environment per call)."""
    if not isinstance(env_id, str):
        raise TypeError(f"an environment id must be a string, got {type(env_id).__name__}")
    if not env_id:
        raise ValueError("an environment id must not be empty")
    if not callable(factory):
        raise TypeError(f"{env_id}: the environment factory must be callable, got {factory!r}")
    if env_id in _registry:
        raise ValueError(f"{env_id} is already registered")
    _registry[env_id] = factory
    registered_envs.append(env_id)


def make(env_id: str, **kwargs: Any) -> tuple[Any, Any]:
    """``(env, env.default_params)`` from the factory registered as ``env_id``."""
    if env_id not in _registry:
        raise ValueError(f"{env_id} is not in registered gymnax environments: {registered_envs}")
    env = _registry[env_id](**kwargs)
    if not all(hasattr(env, name) for name in ("default_params", "reset", "step")):
        raise TypeError(
            f"{env_id}: the factory must return a Gymnax Environment (default_params, reset, "
            f"step), got {type(env).__name__}"
        )
    return env, env.default_params
