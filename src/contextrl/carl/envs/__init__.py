"""CARL's ``carl.envs``: one class per contextrl environment that has a CARL name.

``from contextrl.carl.envs import CARLCartPole`` works for every registered ``CARL…`` alias, so a family
that registers its CARL names appears here with no further code.
"""

from contextrl.carl.envs.carl_env import CARLEnv, carl_class, carl_names


def __getattr__(name: str):
    return carl_class(name)


def __dir__() -> list[str]:
    return sorted({*globals(), *carl_names()})


__all__ = ["CARLEnv", *carl_names()]
