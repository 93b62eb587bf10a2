"""Box2D family: LunarLander, BipedalWalker and VehicleRacing as host environments.

Every context value is held by the environment instance: no module global of gymnasium's Box2D modules is
read or written, so two instances with different contexts in one process stay isolated.
"""

from contextrl.envs.box2d.bipedal_walker import BipedalWalker, BipedalWalkerContext
from contextrl.envs.box2d.garage import GARAGE, VEHICLE_NAMES, Vehicle
from contextrl.envs.box2d.lunar_lander import LunarLander, LunarLanderContext
from contextrl.envs.box2d.vehicle_racing import VehicleRacing, VehicleRacingContext

__all__ = [
    "GARAGE",
    "VEHICLE_NAMES",
    "BipedalWalker",
    "BipedalWalkerContext",
    "LunarLander",
    "LunarLanderContext",
    "Vehicle",
    "VehicleRacing",
    "VehicleRacingContext",
]
