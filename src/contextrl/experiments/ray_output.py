"""Where Ray's own output goes: a run keeps Ray's and Tune's log lines and warnings in its
``ray/ray.log``, and the terminal shows contextrl's progress (``contextrl run --verbose`` shows Ray's)."""

from __future__ import annotations

import contextlib
import logging
import warnings
from collections.abc import Iterator
from typing import TextIO


@contextlib.contextmanager
def ray_output_to(stream: TextIO) -> Iterator[None]:
    """Ray's and Tune's own log lines, what they print and Python's warnings go to ``stream`` (the
    run's ``ray/ray.log``), not the terminal, which shows contextrl's own progress (on stderr)."""
    handler = logging.StreamHandler(stream)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    ray_logger = logging.getLogger("ray")
    saved = ray_logger.handlers[:], ray_logger.propagate
    ray_logger.handlers[:] = [handler]
    ray_logger.propagate = False

    def to_log(message, category, filename, lineno, file=None, line=None):
        stream.write(warnings.formatwarning(message, category, filename, lineno, line))

    try:  # Tune prints its experiment box and result paths to stdout even when silent
        with warnings.catch_warnings(), contextlib.redirect_stdout(stream):
            warnings.showwarning = to_log
            yield
    finally:
        ray_logger.handlers[:], ray_logger.propagate = saved
        handler.flush()
