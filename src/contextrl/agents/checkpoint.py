"""Save and load trained parameters as one ``.npz`` file, written atomically.

Parameters are nested dicts of arrays; each leaf is stored under its path ("actor/layer_0/kernel").
The agent's config and free-form metadata go alongside as JSON, so a checkpoint says what produced it.
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import jax
import numpy as np

_META_KEY = "__contextrl_checkpoint__"


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


def save_checkpoint(
    path: str | os.PathLike, params: Any, config: Any = None, **metadata: Any
) -> Path:
    """Write ``params`` (and the config dataclass, and JSON-able metadata) to ``path`` atomically."""
    path = Path(path)
    if path.suffix != ".npz":
        path = path.with_suffix(path.suffix + ".npz")
    config_dict = dataclasses.asdict(config) if dataclasses.is_dataclass(config) else config
    info = {"config": config_dict, "config_type": type(config).__name__ if config else None}
    info["metadata"] = metadata
    arrays = _flatten(params)
    arrays[_META_KEY] = np.asarray(json.dumps(info))
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as file:
            np.savez(file, **arrays)
            file.flush()
            os.fsync(file.fileno())
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return path


def load_checkpoint(path: str | os.PathLike) -> dict:
    """The parameters saved by :func:`save_checkpoint`, as JAX arrays."""
    with np.load(Path(path), allow_pickle=False) as data:
        return _unflatten({name: data[name] for name in data.files if name != _META_KEY})


def checkpoint_info(path: str | os.PathLike) -> dict:
    """The config (as a dict), its type name and the metadata stored with a checkpoint."""
    with np.load(Path(path), allow_pickle=False) as data:
        return json.loads(str(data[_META_KEY]))
