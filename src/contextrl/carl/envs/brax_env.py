"""CARL's ``CARLBraxEnv``: a Brax task and, for the walkers, CARL's goal variant, on contextrl's Brax family.

A walker's class (Ant, HalfCheetah, Hopper, Humanoid, Walker2d) describes the goal features as CARL's
does: ``target_distance``, ``target_direction`` and ``target_radius``. CARL writes the direction's 16
compass points as numbers (1 north, 2 east, 3 south, 4 west, 12 north-east, 112 north-north-east, ...),
contextrl's goal variant names them ("N", "E", "NE", ...); the face translates both ways, so
``CategoricalContextFeature("target_direction", choices=directions)`` and ``{"target_direction": 1}``
work as in CARL. As in CARL, the goal variant (``crl.make("BraxAnt", goal=True)``: the reward is the
progress toward the target) runs when a context moves the target from its default, or with
``use_language_goals=True``, which adds ``observation["goal"]``, a sentence naming the target; otherwise
the stock task runs, and the goal features are left out of its contexts.
"""

from __future__ import annotations

import string
from typing import Any

import gymnasium

from contextrl.carl.context.context_space import (
    CategoricalContextFeature,
    ContextFeature,
    ContextSpace,
)
from contextrl.carl.envs.carl_env import CARLEnv, built, core_space
from contextrl.carl.utils.types import Context
from contextrl.context.features import ContextError
from contextrl.context.features import ContextSpace as CoreSpace
from contextrl.gymnasium.env import ContextualGymEnv

# CARL's code → contextrl's compass name (north is +y, east +x, the walkers' stock forward)
COMPASS_OF_CODE = {
    1: "N",
    3: "S",
    2: "E",
    4: "W",
    12: "NE",
    32: "SE",
    14: "NW",
    34: "SW",
    112: "NNE",
    332: "SSE",
    114: "NNW",
    334: "SSW",
    212: "ENE",
    232: "ESE",
    414: "WNW",
    434: "WSW",
}
directions = list(COMPASS_OF_CODE)
WORDS = {"N": "north", "S": "south", "E": "east", "W": "west"}
DIRECTION_NAMES = {
    code: " ".join(WORDS[letter] for letter in compass) for code, compass in COMPASS_OF_CODE.items()
}

GOAL_FEATURES = ("target_distance", "target_direction", "target_radius")
SENTENCE_CHARACTERS = string.ascii_letters + string.digits + " .,;-"


def goal_sentence(context: Context) -> str:
    """The target of a goal context in words (CARL's language goals)."""
    where = DIRECTION_NAMES[context["target_direction"]]
    return (
        f"Reach the target {context['target_distance']:g} m to the {where}; "
        f"within {context['target_radius']:g} m of it counts as reached."
    )


class CARLBraxEnv(CARLEnv):
    """A Brax environment with CARL's constructor (``batch_size`` 1: for many copies use contextrl's
    vector environment) and, for the walkers, CARL's goal features and ``use_language_goals``."""

    def __init__(
        self,
        env: Any = None,
        batch_size: int = 1,
        contexts: Any = None,
        obs_context_features: list[str] | None = None,
        obs_context_as_dict: bool = True,
        context_selector: Any = None,
        context_selector_kwargs: dict | None = None,
        use_language_goals: bool = False,
        **kwargs: Any,
    ):
        if batch_size != 1:
            raise ContextError(
                f"batch_size={batch_size!r}: the CARL face steps one copy; for many copies use "
                f"gymnasium.make_vec('contextrl/{self.env_id}-v0', num_envs=...) or crl.make and jax.vmap"
            )
        if not isinstance(use_language_goals, bool):
            raise ContextError(
                f"use_language_goals must be True or False, got {use_language_goals!r}"
            )
        if use_language_goals and not self._goal_options():
            raise ContextError(f"{type(self).__name__} has no goal variant for language goals")
        self.use_language_goals = use_language_goals
        super().__init__(
            env,
            contexts,
            obs_context_features,
            obs_context_as_dict,
            context_selector,
            context_selector_kwargs,
            **kwargs,
        )
        if use_language_goals:
            goal = gymnasium.spaces.Text(max_length=200, charset=SENTENCE_CHARACTERS)
            self.observation_space = gymnasium.spaces.Dict(
                {**self.observation_space.spaces, "goal": goal}
            )

    @classmethod
    def _goal_options(cls) -> dict[str, bool]:
        """``{"goal": True}`` for a walker, whose goal variant's features include the stock task's."""
        return {"goal": True} if getattr(built(cls.env_id), "goal_directions", ()) else {}

    @classmethod
    def _core(cls) -> CoreSpace:
        return core_space(cls.env_id, **cls._goal_options())

    @classmethod
    def _codes(cls) -> dict[int, str]:
        """CARL's direction codes this walker offers → contextrl's compass names."""
        choices = cls._core().features["target_direction"].choices
        return {code: name for code, name in COMPASS_OF_CODE.items() if name in choices}

    @classmethod
    def get_context_features(cls) -> dict[str, ContextFeature]:
        """As ``CARLEnv``'s, with ``target_direction`` in CARL's codes for a walker."""
        features = super().get_context_features()
        if cls._goal_options():
            codes = cls._codes()
            default = {name: code for code, name in codes.items()}[
                cls._core().features["target_direction"].default_label()
            ]
            features["target_direction"] = CategoricalContextFeature(
                "target_direction", choices=list(codes), default_value=default
            )
        return features

    @classmethod
    def get_context_space(cls) -> ContextSpace:
        codes = {"target_direction": cls._codes()} if cls._goal_options() else None
        return ContextSpace(cls.get_context_features(), cls._core(), codes)

    def _build(self) -> ContextualGymEnv:
        """The goal variant when a context moves the target or language goals are asked for, else the
        stock task with the goal features left out."""
        space = self._space()
        contexts = {key: space.inward(c) for key, c in self._contexts.items()}
        if not self._goal_options():
            return self._gym_env(contexts)
        default = space.inward(space.get_default_context())
        moved = any(c[n] != default[n] for c in contexts.values() for n in GOAL_FEATURES)
        if moved or self.use_language_goals:
            return self._gym_env(contexts, goal=True)
        self.obs_context_features = [
            name for name in self.obs_context_features if name not in GOAL_FEATURES
        ]
        stock = {
            key: {n: v for n, v in c.items() if n not in GOAL_FEATURES}
            for key, c in contexts.items()
        }
        return self._gym_env(stock)

    def _observation(self, obs) -> dict[str, Any]:
        observation = super()._observation(obs)
        if self.use_language_goals:
            observation["goal"] = goal_sentence(self._context)
        return observation
