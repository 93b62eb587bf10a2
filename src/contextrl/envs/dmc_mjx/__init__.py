"""The dm_control family on MJX (extra ``dmc``): the stock suite tasks as JAX environments, a context
per copy inside the compiled step; the MuJoCo versions (:mod:`contextrl.envs.dmc`) are their reference.
``crl.make("DmcWalker", backend="mjx")``."""

from contextrl.envs.dmc_mjx.base import DmcMjxEnv, DmcState
from contextrl.envs.dmc_mjx.finger import DmcFingerMjx, DmcFingerMjxContext
from contextrl.envs.dmc_mjx.fish import DmcFishMjx
from contextrl.envs.dmc_mjx.point_mass import DmcPointMassMjx
from contextrl.envs.dmc_mjx.quadruped import DmcQuadrupedMjx
from contextrl.envs.dmc_mjx.walker import DmcWalkerMjx

ENVIRONMENTS = (DmcWalkerMjx, DmcQuadrupedMjx, DmcFishMjx, DmcFingerMjx, DmcPointMassMjx)

__all__ = [
    "ENVIRONMENTS",
    "DmcFingerMjx",
    "DmcFingerMjxContext",
    "DmcFishMjx",
    "DmcMjxEnv",
    "DmcPointMassMjx",
    "DmcQuadrupedMjx",
    "DmcState",
    "DmcWalkerMjx",
]
