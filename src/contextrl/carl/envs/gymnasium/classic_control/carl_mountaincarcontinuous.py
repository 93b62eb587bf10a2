"""CARL's module path for CARLMountainCarContinuous."""

from contextrl.carl.envs.gymnasium.classic_control import CARLMountainCarContinuous

__all__ = ["CARLMountainCarContinuous"]
