"""Loading MuJoCo, MJX and brax without their notices about themselves in the terminal (the
families on MJX, brax's and dm_control's, load through :func:`quiet_mujoco`)."""

from __future__ import annotations

import contextlib
import io
import logging
import warnings


@contextlib.contextmanager
def quiet_mujoco():
    """Brax's, MJX's and MuJoCo's notices about themselves, not about the user's work, kept out of
    the terminal and the current folder while they load: MJX's "Failed to import warp" prints
    (stdout), brax's "not actively maintained" UserWarning, and MuJoCo's compiler deprecation
    warnings on brax's stock models, which MuJoCo's default handler would print and append to
    ./MUJOCO_LOG.TXT. What was held back goes to the ``contextrl`` logger at DEBUG level."""
    import mujoco

    log = logging.getLogger("contextrl")
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda message: log.debug("MuJoCo: %s", message))
    printed = io.StringIO()
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(printed):
            warnings.filterwarnings("ignore", message="Brax System", category=UserWarning)
            yield
    finally:
        mujoco.set_mju_user_warning(previous)
        if printed.getvalue().strip():
            log.debug("MuJoCo/brax import: %s", printed.getvalue().strip())
