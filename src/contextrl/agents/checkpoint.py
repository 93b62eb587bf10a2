"""Save and load trained agents as one ``.npz`` file, written atomically.

Parameters are nested dicts of arrays; each leaf is stored under its path ("actor/layer_0/kernel").
The agent's config and free-form metadata go alongside as JSON, and the training contexts (which
features vary, and their ranges, shape a contextual agent's input) as one array, so a checkpoint says
what produced it and :func:`contextrl.agents.load_policy` can rebuild a ready policy from it alone.
``"runs/agent"`` and ``"runs/agent.npz"`` name the same checkpoint for saving and loading.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any

import jax
import numpy as np

from contextrl.core.files import atomic_write

_META_KEY = "__contextrl_checkpoint__"
_CONTEXTS_KEY = "__contextrl_train_contexts__"


def _flatten(tree: Any, prefix: str = "") -> dict[str, np.ndarray]:
    if isinstance(tree, dict):
        flat = {}
        for name, value in tree.items():
            if not isinstance(name, str) or "/" in name or not name:
                raise ValueError(
                    f"checkpoint keys must be non-empty strings without '/', got {name!r}"
                )
            flat.update(_flatten(value, f"{prefix}{name}/"))
        return flat
    if isinstance(tree, (jax.Array, np.ndarray, np.generic, float, int)):
        return {prefix[:-1]: np.asarray(tree)}
    raise TypeError(
        f"checkpoints hold nested dicts of arrays; found {type(tree).__name__} at {prefix[:-1]!r}"
    )


def _unflatten(flat: dict[str, np.ndarray]) -> dict:
    tree: dict = {}
    for path, value in flat.items():
        node = tree
        *parents, leaf = path.split("/")
        for name in parents:
            node = node.setdefault(name, {})
        node[leaf] = jax.numpy.asarray(value)
    return tree


def checkpoint_path(path: str | os.PathLike) -> Path:
    """The file a checkpoint name refers to: ``.npz`` is added when missing."""
    path = Path(path)
    return path if path.suffix == ".npz" else path.with_suffix(path.suffix + ".npz")


def save_checkpoint(
    path: str | os.PathLike,
    params: Any,
    config: Any = None,
    *,
    train_contexts: Any = None,
    **metadata: Any,
) -> Path:
    """Write ``params``, the config dataclass, the training contexts (a batched context, optional)
    and JSON-able metadata (e.g. ``env="CartPole", agent="ppo"``) to ``path`` atomically."""
    path = checkpoint_path(path)
    config_dict = dataclasses.asdict(config) if dataclasses.is_dataclass(config) else config
    info = {"config": config_dict, "config_type": type(config).__name__ if config else None}
    info["metadata"] = metadata
    arrays = _flatten(params)
    arrays[_META_KEY] = np.asarray(json.dumps(info))
    if train_contexts is not None:
        if not hasattr(getattr(train_contexts, "space", None), "to_array"):
            raise TypeError(
                "train_contexts must be a batch of contexts (e.g. crl.sample(env, spec, n, key)), "
                f"got {type(train_contexts).__name__}"
            )
        arrays[_CONTEXTS_KEY] = np.asarray(train_contexts.space.to_array(train_contexts))

    def write(temporary: str) -> None:
        with open(temporary, "wb") as file:
            np.savez(file, **arrays)
            file.flush()
            os.fsync(file.fileno())

    return atomic_write(path, write)


def _open(path: str | os.PathLike):
    file = checkpoint_path(path)
    if not file.exists():
        raise FileNotFoundError(f"no checkpoint at {file}")
    return np.load(file, allow_pickle=False)


def load_checkpoint(path: str | os.PathLike) -> dict:
    """The parameters saved by :func:`save_checkpoint`, as JAX arrays."""
    with _open(path) as data:
        reserved = (_META_KEY, _CONTEXTS_KEY)
        return _unflatten({name: data[name] for name in data.files if name not in reserved})


def checkpoint_info(path: str | os.PathLike) -> dict:
    """The config (as a dict), its type name and the metadata stored with a checkpoint."""
    with _open(path) as data:
        return json.loads(str(data[_META_KEY]))


def checkpoint_contexts(path: str | os.PathLike, space) -> Any:
    """The training contexts stored with a checkpoint, as a batched context of ``space``."""
    with _open(path) as data:
        if _CONTEXTS_KEY not in data.files:
            return None
        return space.from_array(data[_CONTEXTS_KEY])
