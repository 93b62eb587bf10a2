"""CARL's module path for CARLAcrobot."""

from contextrl.carl.envs.gymnasium.classic_control import CARLAcrobot

__all__ = ["CARLAcrobot"]
