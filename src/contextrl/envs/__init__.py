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


DMC_BACKENDS = ("dm_control", "mjx")


def _make_dmc(name: str, backend: str = "dm_control", **kwargs):
    """Build a dm_control environment: on MuJoCo through dm_control (the default, a host
    environment) or on MJX (``backend="mjx"``, a JAX environment). MuJoCo is imported when the first
    one is made, not on import."""
    if backend == "mjx":
        from contextrl.envs import dmc_mjx

        return getattr(dmc_mjx, f"{name}Mjx")(**kwargs)
    if backend != "dm_control":
        raise ValueError(f"{name}: backend must be one of {DMC_BACKENDS}, got {backend!r}")
    from contextrl.envs import dmc

    return getattr(dmc, name)(**kwargs)


if importlib.util.find_spec("dm_control") is not None:  # the optional `dmc` extra
    for _name in DMC_ENVIRONMENTS:
        _factory = functools.partial(_make_dmc, _name)
        register(
            _name,
            _factory,
            family="dmc",
            aliases=(f"CARL{_name}Env",),
            host=True,
            jax_backends=("mjx",),
        )

# Brax ids: "Brax" + the class name; CARL's names ("CARLBraxAnt", ...) as aliases.
BRAX_ENVIRONMENTS = (
    "Ant",
    "HalfCheetah",
    "Hopper",
    "Walker2d",
    "Humanoid",
    "HumanoidStandup",
    "InvertedPendulum",
    "InvertedDoublePendulum",
    "Reacher",
    "Pusher",
)
REACHING_ENVIRONMENTS = ("Fetch", "Grasp", "Ur5e")
CARL_SPELLINGS = {"HalfCheetah": ("CARLBraxHalfcheetah",)}  # CARL 1.1.1's own class name


def _make_brax(name: str, **kwargs):
    """Build a Brax environment; brax (slow to import) is imported when the first one is made."""
    from contextrl.envs import brax

    return getattr(brax, name)(**kwargs)


if importlib.util.find_spec("brax") is not None:  # the optional `brax` extra
    for _name in BRAX_ENVIRONMENTS:
        _factory = functools.partial(_make_brax, _name)
        carl_names = (f"CARLBrax{_name}", *CARL_SPELLINGS.get(_name, ()))
        register(f"Brax{_name}", _factory, family="brax", aliases=carl_names)
    # The paper's target-reaching tasks, rebuilt on MJX: ids and CARL's names as in CARL 0.x.
    for _name in REACHING_ENVIRONMENTS:
        _factory = functools.partial(_make_brax, _name)
        register(_name, _factory, family="brax", aliases=(f"CARL{_name}",))

BOX2D_ENVIRONMENTS = {  # id: (class name, constructor arguments, CARL's names)
    "LunarLander": ("LunarLander", {}, ("CARLLunarLander",)),
    "LunarLanderContinuous": ("LunarLander", {"continuous": True}, ()),
    "BipedalWalker": ("BipedalWalker", {}, ("CARLBipedalWalker",)),
    "VehicleRacing": ("VehicleRacing", {}, ("CARLVehicleRacing",)),
}


def _make_box2d(name: str, defaults: dict, **kwargs):
    """Build a Box2D environment; Box2D and pygame are imported when the first one is made."""
    from contextrl.envs import box2d

    return getattr(box2d, name)(**{**defaults, **kwargs})


# the optional `box2d` extra (VehicleRacing draws its pixel observations with pygame)
if importlib.util.find_spec("Box2D") is not None and importlib.util.find_spec("pygame") is not None:
    for _id, (_name, _defaults, _aliases) in BOX2D_ENVIRONMENTS.items():
        _factory = functools.partial(_make_box2d, _name, _defaults)
        register(_id, _factory, family="box2d", aliases=_aliases, host=True)


def _make_rna(**kwargs):
    """Build RnaDesign; ViennaRNA is imported when the first one is made, not on import."""
    from contextrl.envs.rna import RnaDesign

    return RnaDesign(**kwargs)


if importlib.util.find_spec("RNA") is not None:  # the optional `rna` extra (viennarna)
    register("RnaDesign", _make_rna, family="rna", aliases=("CARLRnaDesignEnv",), host=True)
