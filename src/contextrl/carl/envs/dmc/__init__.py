"""CARL's ``carl.envs.dmc``: the dm_control environments (with the ``dmc`` extra installed)."""

from contextrl.carl.envs.carl_env import CARLDmcEnv, carl_names, family_getattr

__getattr__ = family_getattr("dmc")
__all__ = ["CARLDmcEnv", *carl_names("dmc")]
