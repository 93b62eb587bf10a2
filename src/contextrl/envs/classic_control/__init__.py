"""Classic control in JAX: gymnasium's five control tasks with every physical constant a context feature."""

from contextrl.envs.classic_control.cartpole import CartPole, CartPoleContext

__all__ = ["CartPole", "CartPoleContext"]
