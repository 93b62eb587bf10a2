"""The dm_control family on MJX (extra ``dmc``): the stock suite tasks as JAX
environments, a context per copy inside the compiled step; the MuJoCo versions
(:mod:`contextrl.envs.dmc`) are their reference. ``crl.make("DmcWalker", backend="mjx")``."""

from contextrl.envs.dmc_mjx.base import DmcMjxEnv
from contextrl.envs.dmc_mjx.walker import DmcWalkerMjx

ENVIRONMENTS = (DmcWalkerMjx,)

__all__ = ["ENVIRONMENTS", "DmcMjxEnv", "DmcWalkerMjx"]
