"""What each compiled program of the gymnasium faces takes and returns, declared once as records.

A program passes one uint32 vector each way (one transfer, see :mod:`contextrl.gymnasium.packing`);
these records are those vectors' layouts. The compiled side builds them, a :class:`Packer` made from
their fields' shapes packs them, and the host reads the same fields back by name.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import numpy as np


def key_data() -> np.ndarray:
    """A run key's data, as the host passes it (:func:`contextrl.gymnasium.env.run_key_bits`)."""
    return np.asarray(jax.random.key_data(jax.random.key(0)))


# ---- the single env's compiled programs (:class:`contextrl.gymnasium.backends.JaxPrograms`) -----------
class Run(NamedTuple):
    """Which run an episode's start belongs to: the run key's data, the global episode, the copies."""

    key: Any
    episode: Any
    copies: Any


class Given(NamedTuple):
    """A context run instead of the selector's choice: its vector and set id (-1: not a member)."""

    context: Any
    context_id: Any


class Started(NamedTuple):
    """An episode's start as a compiled program hands it to the host."""

    carry: Any  # the packed contextual state, which the host passes to the next call
    obs: Any
    context: Any  # the episode's context as a vector
    context_id: Any
    info: dict[str, Any]  # the environment's step facts (``Env.step_info``)


class Stepped(NamedTuple):
    """One step as a compiled program hands it to the host."""

    carry: Any
    obs: Any
    reward: Any
    terminated: Any
    truncated: Any
    info: dict[str, Any]
    context: Any = None  # the step's context as a vector where changes move it; None: the episode's


# ---- a host episode's start (:class:`contextrl.gymnasium.backends.HostPrograms`) ---------------------
class StartRequest(NamedTuple):
    """What a host episode's start asks of :class:`HostPrograms`: the run key's data, the global
    episode and, where ``given`` is 1, the context to run instead of the selector's."""

    key: Any
    episode: Any
    given: Any
    context_id: Any
    context: Any


class HostStart(NamedTuple):
    """A host episode's start: its context (vector and id), the start key's data, the first context
    observation (empty when hidden) and, for scalar physics, the start state and observation."""

    context: Any
    context_id: Any
    start_key: Any
    extra: Any
    state: Any = None
    obs: Any = None


# ---- the vector env's programs (:class:`contextrl.gymnasium.vector.VectorPrograms`) -----------------
class CopySteps(NamedTuple):
    """What a vector program hands the host per copy (one uint32 row each, :meth:`Packer.of_rows`)."""

    obs: Any
    reward: Any
    terminated: Any
    truncated: Any
    final_obs: Any
    final_context_id: Any  # the ended episode's (or the running one's) set index
    context_id: Any  # the running episode's set index
    context: Any  # the running episode's values where resampled; None: the host reads the set
    info: dict[str, Any]  # the environment's facts of the step (``Env.step_info``)
