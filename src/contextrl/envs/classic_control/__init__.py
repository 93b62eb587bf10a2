"""Classic control in JAX: gymnasium's five control tasks with every physical constant a context feature."""

from contextrl.envs.classic_control.acrobot import Acrobot, AcrobotContext
from contextrl.envs.classic_control.cartpole import CartPole, CartPoleContext
from contextrl.envs.classic_control.mountain_car import MountainCar, MountainCarContext
from contextrl.envs.classic_control.mountain_car_continuous import (
    MountainCarContinuous,
    MountainCarContinuousContext,
)
from contextrl.envs.classic_control.pendulum import Pendulum, PendulumContext

__all__ = [
    "Acrobot",
    "AcrobotContext",
    "CartPole",
    "CartPoleContext",
    "MountainCar",
    "MountainCarContext",
    "MountainCarContinuous",
    "MountainCarContinuousContext",
    "Pendulum",
    "PendulumContext",
]
