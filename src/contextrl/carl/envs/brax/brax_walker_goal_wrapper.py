"""CARL's module path for the goal direction's codes (``directions``, ``DIRECTION_NAMES``)."""

from contextrl.carl.envs.brax_env import COMPASS_OF_CODE, DIRECTION_NAMES, directions

__all__ = ["COMPASS_OF_CODE", "DIRECTION_NAMES", "directions"]
