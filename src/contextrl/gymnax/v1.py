"""gymnax 1.0's API: ``step`` returns six values, ``terminated`` and ``truncated`` in place of ``done``.

    import contextrl.gymnax.v1 as gymnax                   # was: import gymnax (1.0)
    env, params = gymnax.make("CartPole-v1")
    obs, state, reward, terminated, truncated, info = env.step(key, state, action, params)

Everything else is ``contextrl.gymnax``'s: params are contexts, the spaces are gymnax's classes when
gymnax is installed, ``registered_envs`` is the same list of ids.
"""

from __future__ import annotations

from typing import Any

from contextrl.gymnax import GYMNAX_IDS, Environment, registered_envs
from contextrl.gymnax import make as make_any


def make(env_id: str, **kwargs: Any) -> tuple[Environment, Any]:
    """``(env, default_params)`` whose ``step`` returns gymnax 1.0's six values (see
    ``contextrl.gymnax.make`` for the ids and keyword arguments)."""
    return make_any(env_id, step_api="1.0", **kwargs)


__all__ = ["GYMNAX_IDS", "Environment", "make", "registered_envs"]
