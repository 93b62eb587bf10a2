"""The dm_control family on MuJoCo (extra ``dmc``): contexts written into the compiled model in place.

Importing this module sets ``MUJOCO_GL=egl`` (headless rendering) unless the variable is already set.
"""

from contextrl.envs.dmc.base import DmcEnv, task_seed
from contextrl.envs.dmc.finger import DmcFinger, DmcFingerContext
from contextrl.envs.dmc.fish import DmcFish, DmcFishContext
from contextrl.envs.dmc.point_mass import DmcPointMass, DmcPointMassContext
from contextrl.envs.dmc.quadruped import DmcQuadruped, DmcQuadrupedContext
from contextrl.envs.dmc.walker import DmcWalker, DmcWalkerContext

ENVIRONMENTS = (DmcWalker, DmcQuadruped, DmcFish, DmcFinger, DmcPointMass)

__all__ = [
    "ENVIRONMENTS",
    "DmcEnv",
    "DmcFinger",
    "DmcFingerContext",
    "DmcFish",
    "DmcFishContext",
    "DmcPointMass",
    "DmcPointMassContext",
    "DmcQuadruped",
    "DmcQuadrupedContext",
    "DmcWalker",
    "DmcWalkerContext",
    "task_seed",
]
