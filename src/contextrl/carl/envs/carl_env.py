"""CARL's environment classes as thin wrappers over contextrl's gymnasium environment.

``CARLEnv`` turns CARL's constructor into a ``ContextualGymEnv`` (which parses and validates the context
set, chooses each episode's context and runs the episode) and reshapes its observation into CARL's
``{"obs": ..., "context": ...}``. The classes of the environments are made from these bases in
``contextrl.carl.envs.registry``.
"""

from __future__ import annotations

import functools
import inspect
import warnings
from collections.abc import Mapping
from typing import Any, ClassVar

import gymnasium
import numpy as np

from contextrl.carl.context.context_space import (
    ContextFeature,
    ContextSpace,
    feature_of,
)
from contextrl.carl.context.selection import (
    BUILT_IN,
    AbstractSelector,
    RoundRobinSelector,
    StaticSelector,
)
from contextrl.carl.utils.types import Context, Contexts
from contextrl.context.features import ContextBase, ContextError
from contextrl.context.features import ContextSpace as CoreSpace
from contextrl.context.schedule import resolve_contexts
from contextrl.core.env import Env
from contextrl.core.host import HostEnv
from contextrl.core.registry import spec
from contextrl.gymnasium.env import ContextualGymEnv


@functools.cache
def built(env_id: str, **options: Any) -> Env | HostEnv:
    """A registered environment with ``options`` (built once per id and options)."""
    return spec(env_id).factory(**options)


def core_space(env_id: str, **options: Any) -> CoreSpace:
    """The context space of a registered environment."""
    return built(env_id, **options).context_space


class CARLEnv(gymnasium.Wrapper):
    """A contextrl environment with CARL's constructor, attributes and observation.

    ``contexts``: a mapping id → dict of feature values (missing features take their defaults; None: the
    default context). ``obs_context_features``: the features shown in the observation (None: all; [] none).
    ``obs_context_as_dict``: the context part of the observation as a dict of features (default) or a
    vector. ``context_selector``: a selector class (built with ``contexts`` and
    ``context_selector_kwargs``) or instance; None is round robin. Other keyword arguments (``max_steps``,
    ``obs_context_normalize``, ``obs_context_noise``, ``changes``, family options) go to
    ``ContextualGymEnv``; with ``changes`` (contexts that move within an episode, contextrl's),
    ``context`` follows the value each step ran under.
    """

    env_id: ClassVar[str]  # the contextrl registry id this class runs

    def __init__(
        self,
        env: Env | HostEnv | None = None,
        contexts: Contexts | None = None,
        obs_context_features: list[str] | None = None,
        obs_context_as_dict: bool = True,
        context_selector: AbstractSelector | type[AbstractSelector] | None = None,
        context_selector_kwargs: dict | None = None,
        **kwargs: Any,
    ):
        if env is not None and not isinstance(env, (Env, HostEnv)):
            raise TypeError(
                f"{type(self).__name__}(env=...) takes None or a contextrl environment such as "
                f"crl.make({self.env_id!r}, max_steps=...), got {type(env).__name__}; the dynamics "
                "are contextrl's, not a gymnasium environment's"
            )
        if env is not None and env.context_space is not self._core():
            raise TypeError(f"{type(self).__name__} runs {self.env_id}, got a {env.name}")
        if not isinstance(obs_context_as_dict, bool):
            raise ContextError(
                f"obs_context_as_dict must be True or False, got {obs_context_as_dict!r}"
            )
        space = self._core()
        names = space.names if obs_context_features is None else obs_context_features
        if isinstance(names, str):
            raise ContextError(f"obs_context_features must be a list of names, got {names!r}")
        self.obs_context_features = [space.resolve(name) for name in names]
        self.obs_context_as_dict = obs_context_as_dict
        self._source = self.env_id if env is None else env
        self._gym_kwargs = {"render_mode": self._class_render_mode(), **kwargs}
        if contexts is None and isinstance(context_selector, AbstractSelector):
            contexts = context_selector.contexts  # CARL runs the contexts its selector was given
        self._contexts = self._fill(contexts)
        self.context_selector = self._selector(context_selector, context_selector_kwargs)
        super().__init__(self._build())
        self.base_observation_space = self._base_space()
        self.observation_space = gymnasium.spaces.Dict(
            {"obs": self.base_observation_space, "context": self._context_space()}
        )
        self._context: Context | None = None
        self._context_id: Any = None
        self._next_id: Any = None

    def __getattr__(self, name: str) -> Any:
        """A public attribute of the environment this class runs (``env.continuous``), as gymnasium
        0.29's wrappers, CARL's base, forwarded them."""
        inner = self.__dict__.get("env")
        if name.startswith("_") or inner is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return getattr(inner.unwrapped, name)

    # ---- construction -------------------------------------------------------------------------------
    @classmethod
    def _core(cls) -> CoreSpace:
        return core_space(cls.env_id)

    @classmethod
    def _class_render_mode(cls) -> str:
        """``CARLPendulum.render_mode = "human"`` (how CARL's demos and tests choose it), else
        "rgb_array"; gymnasium's own ``render_mode`` is a property until a class sets a string. A host
        environment draws frames only (a window beside a simulator's GL context can break it): "human"
        there falls back to "rgb_array", said once."""
        mode = getattr(cls, "render_mode", None)
        if not isinstance(mode, str):
            return "rgb_array"
        if mode == "human" and spec(cls.env_id).host:
            warnings.warn(
                f"{cls.__name__}: {cls.env_id} runs on the host and draws frames only; "
                'render_mode "rgb_array" instead of "human" (render() returns the frame)',
                stacklevel=4,
            )
            return "rgb_array"
        return mode

    def _fill(self, contexts: Contexts | None) -> Contexts:
        """The context set with every feature filled in, validated by contextrl's parser."""
        if contexts is None:
            contexts = {0: {}}
        if not isinstance(contexts, Mapping) or not all(
            isinstance(value, (Mapping, ContextBase)) for value in contexts.values()
        ):
            raise ContextError(
                "contexts must be a mapping id -> dict of feature values (CARL's form), "
                f"got {contexts!r}"
            )
        space = self._space()
        contexts = {
            key: value if isinstance(value, ContextBase) else space.inward(value)
            for key, value in contexts.items()
        }
        members = resolve_contexts(self._core(), contexts).provider.contexts
        return {key: space.plain(members[i]) for i, key in enumerate(contexts)}

    def _selector(self, selector, selector_kwargs) -> AbstractSelector:
        filled = self._contexts
        if selector is None:
            selector = RoundRobinSelector
        if inspect.isclass(selector) and issubclass(selector, AbstractSelector):
            return selector(**{**(selector_kwargs or {}), "contexts": filled})
        if isinstance(selector, AbstractSelector):
            if list(selector.contexts) != list(filled):
                raise ContextError(
                    f"the context selector holds the ids {list(selector.contexts)}, but contexts "
                    f"has {list(filled)}"
                )
            return selector
        raise ContextError(
            "context_selector must be None or a selector class or instance (RoundRobinSelector, "
            f"RandomSelector, StaticSelector, CustomSelector, ...), got {selector!r}"
        )

    @property
    def _core_chooses(self) -> bool:
        """Whether contextrl's core picks each context (the built-in selectors) or ``select()`` does."""
        return type(self.context_selector) in BUILT_IN

    def _build(self) -> ContextualGymEnv:
        space = self._space()
        return self._gym_env({key: space.inward(c) for key, c in self._contexts.items()})

    def _gym_env(self, contexts: Contexts, **options: Any) -> ContextualGymEnv:
        """contextrl's gymnasium environment running ``contexts`` (contextrl's values), built with
        the family ``options``."""
        selector = self.context_selector
        return ContextualGymEnv(
            self._source,
            contexts=contexts,
            context_selector=selector.core_selector() if self._core_chooses else "round_robin",
            obs_context_features=self.obs_context_features or None,
            obs_context_as_dict=bool(self.obs_context_features),
            **self._gym_kwargs,
            **options,
        )

    def _base_space(self) -> gymnasium.spaces.Box:
        inner = self.env.observation_space
        return inner["obs"] if self.obs_context_features else inner

    def _context_space(self) -> gymnasium.spaces.Space:
        if self.obs_context_features:
            box = self.env.observation_space["context"]
        else:
            box = gymnasium.spaces.Box(np.zeros(0, np.float32), np.zeros(0, np.float32))
        if not self.obs_context_as_dict:
            return box
        return gymnasium.spaces.Dict(
            {
                name: gymnasium.spaces.Box(box.low[i : i + 1], box.high[i : i + 1])
                for i, name in enumerate(self.obs_context_features)
            }
        )

    # ---- CARL's class methods -----------------------------------------------------------------------
    @classmethod
    def get_context_features(cls) -> dict[str, ContextFeature]:
        """Every feature with its bounds and default, as CARL's feature classes."""
        return {name: feature_of(cls._core(), name) for name in cls._core().names}

    @classmethod
    def get_context_space(cls) -> ContextSpace:
        """The registered environment's space; for a user's own subclass (no ``env_id``), the space its
        ``get_context_features()`` declares, as in CARL."""
        return ContextSpace(
            cls.get_context_features(), cls._core() if hasattr(cls, "env_id") else None
        )

    @classmethod
    def get_default_context(cls) -> Context:
        return cls._space().get_default_context()

    @classmethod
    def _space(cls) -> ContextSpace:
        """``get_context_space()``, built once per class."""
        if "_context_space_once" not in cls.__dict__:
            cls._context_space_once = cls.get_context_space()
        return cls._context_space_once

    # ---- attributes -------------------------------------------------------------------------------------
    @property
    def contexts(self) -> Contexts:
        """The context set, every feature filled in."""
        return self._contexts

    @contexts.setter
    def contexts(self, contexts: Contexts) -> None:
        """A new context set; the selector starts over on it."""
        self._contexts = self._fill(contexts)
        AbstractSelector.__init__(self.context_selector, self._contexts)
        self.env = self._build()
        self._next_id = None

    @property
    def context(self) -> Context | None:
        """The current episode's context, every feature filled in (None before the first reset)."""
        return self._context

    @context.setter
    def context(self, context: Context) -> None:
        """Checked as every context is (an unknown feature, a value outside its bounds or of the
        wrong type refused, naming it) and filled with defaults. As in CARL, the next reset picks
        from ``contexts``: to run this context, set ``contexts = {0: context}`` or reset with
        ``options={"context": context}``."""
        self._context = self._fill({0: context})[0]

    @property
    def context_id(self) -> Any:
        """The key in ``contexts`` of the current episode's context (None before the first reset)."""
        return self._context_id

    @context_id.setter
    def context_id(self, new_id: Any) -> None:
        """Run the next episode (with a ``StaticSelector``: every later one) under ``contexts[new_id]``."""
        if new_id not in self.contexts:
            raise ContextError(
                f"context_id {new_id!r} is not an id of the context set {list(self.contexts)}"
            )
        self._next_id = new_id

    # ---- gymnasium ----------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        options = dict(options or {})
        chosen, asked = None, False
        if not {"context", "context_id"} & set(options):
            if self._next_id is not None:
                chosen = self._next_id
                if not isinstance(self.context_selector, StaticSelector):
                    self._next_id = None
            elif not self._core_chooses:
                self.context_selector.select()
                chosen, asked = self.context_selector.context_key, True
            if chosen is not None:
                options["context_id"] = chosen
        obs, info = self.env.reset(seed=seed, options=options or None)
        self._context_id = info["context_id"]
        self._context = self._space().outward(info["context"])
        if not asked and self._context_id in self.contexts:
            self.context_selector.record(self._context_id)
        return self._observation(obs), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self.env.changes is not None:
            self._context = self._space().outward(info["context"])
        return self._observation(obs), reward, terminated, truncated, info

    def _observation(self, obs) -> dict[str, Any]:
        """CARL's observation: the original one and the context, as a dict of shape-(1,) arrays or a
        vector (new arrays every call: users keep what they are given)."""
        if not self.obs_context_features:
            empty = {} if self.obs_context_as_dict else np.zeros(0, np.float32)
            return {"obs": obs, "context": empty}
        context = obs["context"]
        if self.obs_context_as_dict:
            context = {name: context[i : i + 1] for i, name in enumerate(self.obs_context_features)}
        return {"obs": obs["obs"], "context": context}


class CARLGymnasiumEnv(CARLEnv):
    """The base of CARL's gymnasium-family environments (classic control, Box2D)."""


class CARLDmcEnv(CARLEnv):
    """The base of CARL's dm_control environments."""
