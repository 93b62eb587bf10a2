"""CARL's module path for CARLVehicleRacing."""

from contextrl.carl.envs.gymnasium.box2d import CARLVehicleRacing

__all__ = ["CARLVehicleRacing"]
