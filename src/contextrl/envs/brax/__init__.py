"""The Brax family (extra ``brax``): ten locomotion and control tasks on brax's physics, MJX by default.

Every copy of a batch runs its own physical system, built from its context inside the compiled step.
"""

from contextrl.envs.brax.base import BACKENDS, COMPASS, BraxEnv, context_class, load_brax_env
from contextrl.envs.brax.environments import (
    Ant,
    HalfCheetah,
    Hopper,
    Humanoid,
    HumanoidStandup,
    InvertedDoublePendulum,
    InvertedPendulum,
    Pusher,
    Reacher,
    Walker2d,
)

ENVIRONMENTS = (
    Ant,
    HalfCheetah,
    Hopper,
    Walker2d,
    Humanoid,
    HumanoidStandup,
    InvertedPendulum,
    InvertedDoublePendulum,
    Reacher,
    Pusher,
)

__all__ = [
    "BACKENDS",
    "COMPASS",
    "ENVIRONMENTS",
    "Ant",
    "BraxEnv",
    "HalfCheetah",
    "Hopper",
    "Humanoid",
    "HumanoidStandup",
    "InvertedDoublePendulum",
    "InvertedPendulum",
    "Pusher",
    "Reacher",
    "Walker2d",
    "context_class",
    "load_brax_env",
]
