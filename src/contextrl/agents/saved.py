"""A saved agent brought back ready to act: ``load_policy("runs/x/checkpoints/trial.npz")``.

The checkpoint names its agent and environment and holds its config and training contexts, so the
config comes back as the agent's dataclass, the environment is rebuilt by name, and the policy is made
exactly as it was for training (same context input, same normalisation).
"""

from __future__ import annotations

import dataclasses
import os
import typing
from typing import Any

import jax

from contextrl.agents.checkpoint import checkpoint_contexts, checkpoint_info, load_checkpoint
from contextrl.agents.evaluation import evaluate
from contextrl.agents.registry import get_agent


@dataclasses.dataclass(frozen=True)
class SavedPolicy:
    """A trained agent: ``policy(params, obs, ctx, key)`` with its params, config and environment."""

    agent: str
    env_id: str
    env: Any
    config: Any
    params: Any
    train_contexts: Any
    policy: Any
    metadata: dict

    def act(self, obs, ctx, key) -> jax.Array:
        """The action for one observation under context ``ctx``."""
        return self.policy(self.params, obs, ctx, key)

    def evaluate(self, contexts, episodes: int, key) -> jax.Array:
        """Mean return per context of ``contexts`` (a batched context of this environment)."""
        return evaluate(self.policy, self.params, self.env, contexts, episodes, key)


def _rebuild_config(config_type: type, values: dict) -> Any:
    """The config dataclass from its JSON dict (lists back to tuples where the field is a tuple)."""
    hints = typing.get_type_hints(config_type)
    if "obs_context" in values and "variant" not in values:  # saved before the field was renamed
        values = {("variant" if k == "obs_context" else k): v for k, v in values.items()}
    fixed = {
        name: tuple(value) if isinstance(value, list) and "tuple" in str(hints.get(name)) else value
        for name, value in values.items()
    }
    config = config_type(**fixed)
    config.validate()
    return config


def load_policy(path: str | os.PathLike) -> SavedPolicy:
    """The agent saved at ``path`` (``.npz`` optional), rebuilt and ready to act or evaluate."""
    import contextrl as crl

    info = checkpoint_info(path)
    metadata = info.get("metadata") or {}
    missing = [k for k in ("agent", "env") if k not in metadata]
    if missing:
        raise ValueError(
            f"{path}: the checkpoint does not name its {' and '.join(missing)}; save it with "
            "save_checkpoint(path, params, config, train_contexts=..., agent=..., env=...)"
        )
    options = {"backend": metadata["backend"]} if metadata.get("backend") else {}
    if crl.spec(metadata["env"]).runs_on_host(options):
        raise ValueError(
            f"{path}: {metadata['env']} is a host environment; load_policy rebuilds JAX policies. "
            "Evaluate a host run's agents with: contextrl eval RUN --test FEATURE=DIST"
        )
    agent = get_agent(metadata["agent"])
    max_steps = metadata.get("max_steps")
    env = crl.make(
        metadata["env"], **options, **({} if max_steps is None else {"max_steps": max_steps})
    )
    config = None
    if agent.config_type is not None and info.get("config") is not None:
        config = _rebuild_config(agent.config_type, info["config"])
    contexts = checkpoint_contexts(path, env.context_space)
    if contexts is None:
        contexts = env.context_space.stack([env.context_space.default()])
    policy = agent.make_policy(config, env, contexts)
    return SavedPolicy(
        agent=agent.name,
        env_id=metadata["env"],
        env=env,
        config=config,
        params=load_checkpoint(path),
        train_contexts=contexts,
        policy=policy,
        metadata=metadata,
    )
