"""CARL's ``carl.envs.gymnasium``: the gymnasium-family environments (classic control, Box2D)."""

from contextrl.carl.envs.carl_env import CARLGymnasiumEnv
from contextrl.carl.envs.registry import carl_classes, carl_names, family_getattr

FAMILIES = ("classic_control", "box2d")

globals().update(carl_classes(*FAMILIES))
__getattr__ = family_getattr(*FAMILIES)
__all__ = ["CARLGymnasiumEnv", *(name for family in FAMILIES for name in carl_names(family))]
