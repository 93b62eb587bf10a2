"""The Brax family (extra ``brax``): brax's ten locomotion and control tasks on its physics, MJX by
default, and the paper's target-reaching tasks (Fetch, Grasp, UR5e) rebuilt on MJX.

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
from contextrl.envs.brax.fetch import Fetch
from contextrl.envs.brax.grasp import Grasp
from contextrl.envs.brax.reaching import ReachingTask
from contextrl.envs.brax.ur5e import Ur5e

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
REACHING_ENVIRONMENTS = (Fetch, Grasp, Ur5e)

__all__ = [
    "BACKENDS",
    "COMPASS",
    "ENVIRONMENTS",
    "REACHING_ENVIRONMENTS",
    "Ant",
    "BraxEnv",
    "Fetch",
    "Grasp",
    "HalfCheetah",
    "Hopper",
    "Humanoid",
    "HumanoidStandup",
    "InvertedDoublePendulum",
    "InvertedPendulum",
    "Pusher",
    "ReachingTask",
    "Reacher",
    "Ur5e",
    "Walker2d",
    "context_class",
    "load_brax_env",
]
