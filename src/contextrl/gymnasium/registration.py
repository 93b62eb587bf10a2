"""Every contextrl environment under gymnasium's ids: ``contextrl/<Id>-v0`` and its CARL aliases.

Registration reads the contextrl registry when it runs, and runs again harmlessly, so environments
registered after the first call (a family imported later, a user's own) appear on the next call.
``import contextrl`` calls it once every family has registered.
"""

from __future__ import annotations

import gymnasium

from contextrl.core.registry import registered, spec

NAMESPACE = "contextrl"
VERSION = 0


def gym_id(env_id: str) -> str:
    """The gymnasium id of a contextrl id or alias: ``CartPole`` → ``contextrl/CartPole-v0``."""
    return f"{NAMESPACE}/{env_id}-v{VERSION}"


def register_envs() -> list[str]:
    """Register every contextrl id and alias not yet known to gymnasium; returns the new gymnasium ids.

    The time limit belongs to the environment (``max_steps=``), so no ``TimeLimit`` wrapper is added.
    """
    added = []
    for env_id in registered():
        for name in (env_id, *spec(env_id).aliases):
            gymnasium_id = gym_id(name)
            if gymnasium_id in gymnasium.registry:
                continue
            gymnasium.register(
                gymnasium_id,
                entry_point="contextrl.gymnasium.env:ContextualGymEnv",
                vector_entry_point="contextrl.gymnasium.vector:make_vector_env",
                kwargs={"env_id": env_id},
                max_episode_steps=None,
            )
            added.append(gymnasium_id)
    return added
