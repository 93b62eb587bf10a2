"""CARL's module path for CARLLunarLander."""

from contextrl.carl.envs.gymnasium.box2d import CARLLunarLander

__all__ = ["CARLLunarLander"]
