"""JAX's persistent compilation cache, on for the ``contextrl`` command, the experiment runner and its
workers: a second run of the same spec, a restarted worker or a resumed run loads its compiled
programs from disk instead of compiling them again (compiling is most of a short run's time on CPU).

The cache lives in ``$CONTEXTRL_CACHE_DIR/jax``, else ``$XDG_CACHE_HOME/contextrl/jax``, else
``~/.cache/contextrl/jax``; a process that already chose a cache (``JAX_COMPILATION_CACHE_DIR`` or
``jax.config``) keeps its own. Entries are keyed by the program, the jaxlib version and the XLA flags,
so a stale entry is never used. ``contextrl cache`` shows it, ``contextrl cache clear`` empties it.
Importing contextrl changes nothing; library users turn it on with :func:`use_compilation_cache`.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import jax

MAX_BYTES = 4 * 1024**3  # past this, JAX deletes the least recently used entries
MIN_COMPILE_SECONDS = 0.3  # programs that compile faster are not worth a file


def default_cache_dir() -> Path:
    """Where contextrl keeps compiled programs (see the module's docstring)."""
    root = os.environ.get("CONTEXTRL_CACHE_DIR")
    if not root:
        xdg = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
        root = str(Path(xdg) / "contextrl")
    return Path(root).expanduser() / "jax"


def use_compilation_cache() -> Path:
    """Turn JAX's persistent compilation cache on in this process, unless it already has one; returns
    the cache's folder. Takes effect for programs compiled afterwards."""
    chosen = jax.config.jax_compilation_cache_dir
    if chosen:
        return Path(chosen)
    path = default_cache_dir()
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
    jax.config.update("jax_compilation_cache_max_size", MAX_BYTES)
    return path


def cache_contents(path: Path) -> tuple[int, int]:
    """(files, bytes) in a cache folder; (0, 0) where it does not exist."""
    files = [p for p in path.rglob("*") if p.is_file()] if path.is_dir() else []
    return len(files), sum(p.stat().st_size for p in files)


def clear_cache(path: Path) -> tuple[int, int]:
    """Delete a cache folder; returns the (files, bytes) it held."""
    contents = cache_contents(path)
    if path.is_dir():
        shutil.rmtree(path)
    return contents
