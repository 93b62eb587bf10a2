"""Atomic file writes that respect the user's umask.

``tempfile.mkstemp`` creates files with mode 0600 whatever the umask; a result, checkpoint or GIF that
only its writer can read surprises everyone who shares a run directory. Every writer in the package goes
through :func:`atomic_write`: write to a temporary name in the same folder, set the mode ``open()`` would
have given, rename into place. A process killed at any moment leaves only whole files.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable
from pathlib import Path


def umask_mode(base: int = 0o666) -> int:
    """The mode a new file gets from ``open()`` under the current umask."""
    mask = os.umask(0)
    os.umask(mask)
    return base & ~mask


def atomic_write(path: str | os.PathLike, write: Callable[[str], None]) -> Path:
    """Call ``write(temporary_path)``, give it the umask's mode, then rename it onto ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(handle)
    try:
        write(temporary)
        os.chmod(temporary, umask_mode())
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        raise
    return path
