"""CARL's module path for CARLBipedalWalker."""

from contextrl.carl.envs.gymnasium.box2d import CARLBipedalWalker

__all__ = ["CARLBipedalWalker"]
