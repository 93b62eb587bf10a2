"""CARL's module path for CARLMountainCar."""

from contextrl.carl.envs.gymnasium.classic_control import CARLMountainCar

__all__ = ["CARLMountainCar"]
