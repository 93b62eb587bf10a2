"""CARL's ``carl.envs.dmc``: the dm_control environments (with the ``dmc`` extra installed)."""

from contextrl.carl.envs.carl_env import CARLDmcEnv
from contextrl.carl.envs.registry import carl_classes, carl_names, family_getattr

globals().update(carl_classes("dmc"))
__getattr__ = family_getattr("dmc")
__all__ = ["CARLDmcEnv", *carl_names("dmc")]
