"""CARL's ``carl.envs.gymnasium.box2d`` (with the ``box2d`` extra installed)."""

from contextrl.carl.envs.registry import carl_classes, carl_names, family_getattr

globals().update(carl_classes("box2d"))
__getattr__ = family_getattr("box2d")
__all__ = carl_names("box2d")
