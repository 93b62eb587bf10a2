"""CARL's module path for ``CARLBraxEnv``."""

from contextrl.carl.envs.brax_env import CARLBraxEnv, goal_sentence

__all__ = ["CARLBraxEnv", "goal_sentence"]
