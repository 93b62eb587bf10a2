"""The settings the paper's figures were trained with, as the authors' experiment configs state them.

The paper's agents are coax's (CARL's ``experiments/context_gating/algorithms``), configured by
Hydra files under ``experiments/benchmarking/configs`` in automl/CARL. Where the paper's appendix
table and those files disagree (dm_control's SAC settings: the table repeats Pendulum's), the files
are what produced the figures, so :func:`contextrl.agents.dqn.paper_config` and
:func:`contextrl.agents.sac.paper_config` follow the files, and each setting names the files it
merges, the later overriding the earlier, as Hydra's ``defaults`` lists do.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

CARL_COMMIT = "d4f7ab81"
CARL_CONFIGS = f"automl/CARL at {CARL_COMMIT}, experiments/benchmarking/configs"


@dataclasses.dataclass(frozen=True)
class AuthorsSetting:
    """One environment's agent settings from the authors' config files."""

    files: tuple[str, ...]
    """Config files under :data:`CARL_CONFIGS`, the later overriding the earlier."""
    frames: int
    """The training budget the files state (``max_num_frames``)."""
    options: Mapping[str, Any]
    """The same settings as this library's agent config fields."""

    @property
    def source(self) -> str:
        """Where the settings come from, as a spec's settings line cites it."""
        return f"{CARL_CONFIGS}/{{{', '.join(self.files)}}}"
