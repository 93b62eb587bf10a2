"""CARL's ``carl.envs.brax`` (with the ``brax`` extra installed): one class per Brax environment."""

from contextrl.carl.envs.registry import carl_classes, carl_names, family_getattr

globals().update(carl_classes("brax"))
__getattr__ = family_getattr("brax")
__all__ = carl_names("brax")
