"""CARL's ``carl.envs.gymnasium.classic_control``."""

from contextrl.carl.envs.registry import carl_class

CARLAcrobot = carl_class("CARLAcrobot")
CARLCartPole = carl_class("CARLCartPole")
CARLMountainCar = carl_class("CARLMountainCar")
CARLMountainCarContinuous = carl_class("CARLMountainCarContinuous")
CARLPendulum = carl_class("CARLPendulum")

__all__ = [
    "CARLAcrobot",
    "CARLCartPole",
    "CARLMountainCar",
    "CARLMountainCarContinuous",
    "CARLPendulum",
]
