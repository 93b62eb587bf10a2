"""Environment families; importing this registers every environment whose dependencies are installed."""

from contextrl.core.registry import register
from contextrl.envs import classic_control

register("CartPole", classic_control.CartPole, family="classic_control", aliases=("CARLCartPole",))
