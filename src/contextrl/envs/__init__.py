"""Environment families; importing this registers every environment whose dependencies are installed."""

import importlib.util

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

if importlib.util.find_spec("dm_control") is not None:  # the optional `dmc` extra
    from contextrl.envs import dmc

    for _env in dmc.ENVIRONMENTS:
        register(_env.__name__, _env, family="dmc", aliases=(f"CARL{_env.__name__}Env",), host=True)
