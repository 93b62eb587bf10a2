"""The environment registry: ``crl.make(id)`` for every family, CARL's ids as aliases."""

from __future__ import annotations

import dataclasses
import difflib
import json
import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

# The rows of every environment the package ships, installed or not, written by
# tools/write_environment_index.py and tested to equal what building each environment gives:
# `contextrl list` reads them instead of building every simulator (seconds each for MuJoCo's and
# Brax's), and an unregistered id found there names the extra it needs.
ENVIRONMENT_INDEX = Path(__file__).resolve().parents[1] / "environments.json"
# The families an extra brings (pip install "contextrl[<family>]"): their simulators are optional.
EXTRA_FAMILIES = ("box2d", "brax", "dmc", "rna")

# The families whose environments take a ``backend`` argument (their simulator's pipeline).
BACKEND_FAMILIES = {"brax": "Brax", "dmc": "dm_control"}


@dataclasses.dataclass(frozen=True)
class EnvSpec:
    """A registered environment: its id, family, how to build it, and other names it answers to."""

    id: str
    family: str
    factory: Callable[..., Any]
    aliases: tuple[str, ...] = ()
    host: bool = False  # True for environments stepped on the CPU outside JAX (Box2D, MuJoCo, …)
    # Values of a host environment's ``backend`` argument that build a JAX environment instead (MJX).
    jax_backends: tuple[str, ...] = ()

    def check_backend(self, backend: Any, option: str) -> None:
        """Refuse ``backend`` (given as ``option``) for an environment of a family without one."""
        if backend is not None and self.family not in BACKEND_FAMILIES:
            families = " and ".join(BACKEND_FAMILIES.values())
            raise ValueError(
                f"{option} {backend!r}: only the {families} environments have a backend; "
                f"{self.id} ({self.family}) has none"
            )

    def runs_on_host(self, kwargs: Mapping[str, Any] | None = None) -> bool:
        """Whether the environment built with ``kwargs`` is a host environment."""
        return self.host and (kwargs or {}).get("backend") not in self.jax_backends

    def build(self, **kwargs: Any):
        """The environment, built with ``kwargs``; an argument its constructor does not take is
        refused in one line (``context=`` points at ``contexts=``)."""
        try:
            return self.factory(**kwargs)
        except TypeError as error:
            unknown = re.search(r"unexpected keyword argument '(\w+)'", str(error))
            if unknown is None or unknown.group(1) not in kwargs:  # not the caller's argument
                raise
        name = unknown.group(1)
        hints = {  # only a host environment's constructor lacks max_steps
            "context": "; a context is given as contexts= (a dict, a list of them, or distributions)",
            "max_steps": "; a host environment's time limit is set where it is stepped: "
            f"ContextualGymEnv({self.id!r}, max_steps=N), or max_steps in a run's spec",
        }
        hint = hints.get(name, "")
        raise ValueError(f"{self.id}: unknown argument {name!r}{hint}") from None


_REGISTRY: dict[str, EnvSpec] = {}
_ALIASES: dict[str, str] = {}


def register(
    id: str,
    factory: Callable[..., Any],
    *,
    family: str,
    aliases: Sequence[str] = (),
    host: bool = False,
    jax_backends: Sequence[str] = (),
) -> None:
    """Add an environment; ids and aliases must be unique."""
    for name in (id, *aliases):
        if name in _REGISTRY or name in _ALIASES:
            raise ValueError(f"environment id {name!r} is already registered")
    _REGISTRY[id] = EnvSpec(id, family, factory, tuple(aliases), host, tuple(jax_backends))
    for alias in aliases:
        _ALIASES[alias] = id


def _uninstalled_family(id: str) -> str | None:
    """The optional family of a shipped environment that is not registered (its extra missing)."""
    if not ENVIRONMENT_INDEX.exists():
        return None
    entry = json.loads(ENVIRONMENT_INDEX.read_text(encoding="utf-8")).get(id)
    family = entry and entry.get("family")
    return family if family in EXTRA_FAMILIES else None


def spec(id: str) -> EnvSpec:
    """The registered spec for an id or alias, or a clear error listing the valid ids."""
    canonical = _ALIASES.get(id, id)
    if canonical not in _REGISTRY:
        # "cartpole" finds CartPole when exactly one id or alias matches regardless of case
        lower = str(id).lower()
        matches = {_ALIASES.get(n, n) for n in (*_REGISTRY, *_ALIASES) if n.lower() == lower}
        if len(matches) == 1:
            (canonical,) = matches
    if canonical not in _REGISTRY:
        family = _uninstalled_family(id)
        if family:
            raise KeyError(
                f"environment {id!r} is in the {family} family, whose simulator is not installed: "
                f'pip install "contextrl[{family}]"'
            )
        close = difflib.get_close_matches(id, [*_REGISTRY, *_ALIASES], n=3)
        hint = f" Did you mean {close}?" if close else ""
        raise KeyError(f"unknown environment {id!r}.{hint} Registered: {sorted(_REGISTRY)}")
    return _REGISTRY[canonical]


def registered(family: str | None = None) -> list[str]:
    """Registered ids (not aliases), optionally of one family, sorted."""
    return sorted(i for i, s in _REGISTRY.items() if family is None or s.family == family)


def make(
    id: str,
    *,
    obs_context_features: None | str | Sequence[str] = None,
    obs_context_normalize: bool = False,
    obs_context_noise: float = 0.0,
    contexts: Any = None,
    **kwargs: Any,
):
    """Build a registered environment.

    ``obs_context_features`` appends context features to the observation: None (hidden, the original
    observation), "all", "varying" (needs ``contexts``, the features that differ across that set), or a
    list of names. Other keyword arguments (``max_steps``, family options) go to the constructor.
    """
    env = spec(id).build(**kwargs)
    if obs_context_features is not None or obs_context_noise or obs_context_normalize:
        env = env.with_obs_context(
            obs_context_features,
            contexts=contexts,
            normalize=obs_context_normalize,
            noise=obs_context_noise,
        )
    return env
