"""CARL's environment classes, one per contextrl environment registered with a ``CARL…`` name.

Each class is made from the registry on first use (its base by family), so a family that registers its
CARL names has its classes, modules and ``carl/<Name>-v0`` gymnasium ids with nothing written per
environment.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import gymnasium

from contextrl.carl.envs.brax_env import CARLBraxEnv
from contextrl.carl.envs.carl_env import CARLDmcEnv, CARLEnv, CARLGymnasiumEnv
from contextrl.core.registry import registered, spec

FAMILY_BASES: dict[str, type[CARLEnv]] = {"dmc": CARLDmcEnv, "brax": CARLBraxEnv}


@functools.cache
def carl_class(name: str) -> type[CARLEnv]:
    """The CARL class of a registered ``CARL…`` alias (``CARLCartPole``, ``CARLDmcWalkerEnv``)."""
    names = carl_names()
    if name not in names:
        raise AttributeError(f"no CARL environment {name!r}; available: {names}")
    env_spec = spec(name)
    base = FAMILY_BASES.get(env_spec.family, CARLGymnasiumEnv)
    return type(
        name,
        (base,),
        {
            "env_id": env_spec.id,
            "__doc__": f"CARL's {name} running contextrl's {env_spec.id} (see CARLEnv).",
            "__module__": "contextrl.carl.envs",
        },
    )


def carl_names(family: str | None = None) -> list[str]:
    """Every registered ``CARL…`` alias, optionally of one family."""
    return [
        alias
        for env_id in registered(family)
        for alias in spec(env_id).aliases
        if alias.startswith("CARL")
    ]


def carl_classes(*families: str) -> dict[str, type[CARLEnv]]:
    """Name → CARL class for some families (every family when none): a CARL module's attributes."""
    names = [n for family in families for n in carl_names(family)] if families else carl_names()
    return {name: carl_class(name) for name in names}


def family_getattr(*families: str) -> Callable[[str], type[CARLEnv]]:
    """A module ``__getattr__`` for names that are not among its classes: an error listing them."""

    def module_getattr(name: str) -> type[CARLEnv]:
        names = [n for family in families for n in carl_names(family)]
        if name not in names:
            raise AttributeError(f"no CARL environment {name!r} here; available: {names}")
        return carl_class(name)

    return module_getattr


def register_carl_ids() -> list[str]:
    """Register ``carl/<Name>-v0`` with gymnasium for every CARL class not yet known to it, as importing
    CARL does, so ``gymnasium.make("carl/CARLCartPole-v0")`` builds the face's class; returns the new ids."""
    added = []
    for name in carl_names():
        gymnasium_id = f"carl/{name}-v0"
        if gymnasium_id not in gymnasium.registry:
            gymnasium.register(gymnasium_id, entry_point=f"contextrl.carl.envs:{name}")
            added.append(gymnasium_id)
    return added
