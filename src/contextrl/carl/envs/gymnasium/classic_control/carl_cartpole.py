"""CARL's module path for CARLCartPole."""

from contextrl.carl.envs.gymnasium.classic_control import CARLCartPole

__all__ = ["CARLCartPole"]
