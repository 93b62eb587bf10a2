"""Environment families; importing this registers every environment whose dependencies are installed."""

from contextrl.core.registry import register
from contextrl.envs import classic_control

for _env in (
    classic_control.CartPole,
    classic_control.Pendulum,
    classic_control.MountainCar,
    classic_control.MountainCarContinuous,
    classic_control.Acrobot,
):
    register(_env.__name__, _env, family="classic_control", aliases=(f"CARL{_env.__name__}",))
