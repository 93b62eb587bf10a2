"""Environment families; importing this registers every environment whose dependencies are installed."""

import functools
import importlib.util

from contextrl.core.registry import register
from contextrl.envs import classic_control, platformer

for _env in (
    classic_control.CartPole,
    classic_control.Pendulum,
    classic_control.MountainCar,
    classic_control.MountainCarContinuous,
    classic_control.Acrobot,
):
    register(_env.__name__, _env, family="classic_control", aliases=(f"CARL{_env.__name__}",))

register("Platformer", platformer.Platformer, family="platformer", aliases=("CARLMarioEnv",))

DMC_ENVIRONMENTS = ("DmcWalker", "DmcQuadruped", "DmcFish", "DmcFinger", "DmcPointMass")


def _make_dmc(name: str, **kwargs):
    """Build a dm_control environment; MuJoCo is imported when the first one is made, not on import."""
    from contextrl.envs import dmc

    return getattr(dmc, name)(**kwargs)


if importlib.util.find_spec("dm_control") is not None:  # the optional `dmc` extra
    for _name in DMC_ENVIRONMENTS:
        _factory = functools.partial(_make_dmc, _name)
        register(_name, _factory, family="dmc", aliases=(f"CARL{_name}Env",), host=True)
