"""The platformer family: a Mario-like game in JAX whose levels are generated from the context."""

from contextrl.envs.platformer.env import Platformer
from contextrl.envs.platformer.world import (
    ACTION_NAMES,
    STYLES,
    PlatformerContext,
    PlatformerState,
    level_map,
)

__all__ = [
    "ACTION_NAMES",
    "STYLES",
    "Platformer",
    "PlatformerContext",
    "PlatformerState",
    "level_map",
]
