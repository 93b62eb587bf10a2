"""CARL's module path for CARLPendulum."""

from contextrl.carl.envs.gymnasium.classic_control import CARLPendulum

__all__ = ["CARLPendulum"]
