"""CARL's ``carl.envs``: one class per contextrl environment that has a CARL name.

``from contextrl.carl.envs import CARLCartPole`` works for every registered ``CARL…`` alias, so a family
that registers its CARL names appears here with no further code. The classes are module attributes (as in
CARL's module, ``vars()`` lists them, and as there every ``CARL…`` name here is an environment: the base
class is ``contextrl.carl.envs.carl_env.CARLEnv``); building them reads only the registry, importing no
simulator.
"""

from contextrl.carl.envs.registry import carl_class, carl_classes, carl_names

globals().update(carl_classes())


def __getattr__(name: str):
    """Only a name that is no CARL class gets here: an error listing the available ones."""
    return carl_class(name)


__all__ = carl_names()
