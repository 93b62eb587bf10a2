"""One host stepping loop for every agent: N copies of a registered environment through gymnasium's
public vector API, for environments that are not JAX functions (dm_control, Box2D, RNA…).

    collector = HostCollector("DmcWalker", num_envs=4, contexts=contexts, context_obs="concat_all")
    step = collector.step(env_actions)      # obs, context input, rewards, ends, final observations

The collector owns what every agent's host training needs and nothing algorithm-specific: the vector
env (``gymnasium.make_vec("contextrl/<Id>-v0", num_envs=N, contexts=...)``, same-step auto-reset), the
agent's context input read from ``info["context"]`` and normalised by the feature bounds as on the JAX
path, and the episode bookkeeping behind training curves. Agents add only acting and learning.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import gymnasium
import jax
import numpy as np

from contextrl.agents.networks import ContextInput, context_input
from contextrl.context.distributions import DISTRIBUTIONS
from contextrl.gymnasium.registration import gym_id


@dataclasses.dataclass(frozen=True)
class HostStep:
    """One vector step. ``final_obs`` is the last observation of an ended episode and ``next_obs``
    elsewhere (what a learner bootstraps from); ``obs``/``context`` are the inputs for the next action."""

    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    final_obs: np.ndarray
    obs: np.ndarray
    context: np.ndarray

    @property
    def done(self) -> np.ndarray:
        return self.terminated | self.truncated


class HostCollector:
    """N copies of ``env_id`` stepped on the host, with context input and episode bookkeeping."""

    def __init__(
        self,
        env_id: str,
        num_envs: int,
        contexts: Any,
        context_obs: str = "hidden",
        *,
        selector: str = "random",
        seed: int = 0,
        vectorization: str = "sync",
        context: ContextInput | None = None,
        **env_kwargs: Any,
    ):
        """``context`` fixes the agent's context input (an agent trained on other contexts sees
        the features it was trained with); by default it follows ``context_obs`` and ``contexts``."""
        resampled = isinstance(contexts, Mapping) and any(
            isinstance(v, DISTRIBUTIONS) for v in contexts.values()
        )
        choice = {} if resampled else {"context_selector": selector}
        self.envs = gymnasium.make_vec(
            gym_id(env_id),
            num_envs=num_envs,
            contexts=contexts,
            vectorization=vectorization,
            **choice,
            **env_kwargs,
        )
        self.num_envs = num_envs
        self.space = (
            getattr(self.envs, "context_space", None) or self.envs.get_attr("context_space")[0]
        )
        if context is None:
            context = context_input(context_obs, self.space, contexts)
        self.context_input = context
        self._lower = np.asarray(context.lower, np.float32)
        self._span = np.maximum(np.asarray(context.upper, np.float32) - self._lower, 1e-8)
        self._names = [self.space.names[i] for i in context.indices]
        self.steps = 0
        self._running_return = np.zeros(num_envs)
        self._running_length = np.zeros(num_envs, np.int64)
        self._episodes: list[tuple[float, int, int, int]] = []
        self._period_start = 0
        self._last_curve = (0.0, 0.0)
        obs, info = self.envs.reset(seed=seed)
        self.obs, self.context = np.asarray(obs, np.float32), self._context_input(info)

    @property
    def single_action_space(self):
        return self.envs.single_action_space

    @property
    def single_observation_space(self):
        return self.envs.single_observation_space

    def _context_input(self, info) -> np.ndarray:
        columns = []
        for name in self._names:
            values = np.asarray(info["context"][name])
            if values.dtype == object:  # categorical features arrive as choice names
                values = np.array([self.space.features[name].choices.index(v) for v in values])
            columns.append(values.astype(np.float32))
        if not columns:
            return np.zeros((self.num_envs, 0), np.float32)
        return np.clip((np.stack(columns, axis=-1) - self._lower) / self._span, 0.0, 1.0)

    def step(self, env_actions) -> HostStep:
        """Step every copy with ``env_actions`` (in the environment's action space)."""
        obs, reward, terminated, truncated, info = self.envs.step(np.asarray(env_actions))
        terminated, truncated = np.asarray(terminated), np.asarray(truncated)
        reward = np.asarray(reward, np.float32)
        obs = np.asarray(obs, np.float32)
        done = terminated | truncated
        final = obs.copy()
        for i in np.flatnonzero(done):
            final[i] = info["final_obs"][i]
        self.steps += self.num_envs
        self._running_return += reward
        self._running_length += 1
        for i in np.flatnonzero(done):
            context_id = int(info["final_info"]["context_id"][i])
            self._episodes.append(
                (
                    float(self._running_return[i]),
                    int(self._running_length[i]),
                    context_id,
                    self.steps,
                )
            )
        self._running_return[done], self._running_length[done] = 0.0, 0
        self.obs, self.context = obs, self._context_input(info)
        return HostStep(reward, terminated, truncated, final, obs, self.context)

    def close_period(self) -> dict[str, float]:
        """The training-curve row of the episodes that ended since the last call; when none did, the
        last row's values (before any episode ended: the running episodes' so far), never NaN."""
        ended = self._episodes[self._period_start :]
        self._period_start = len(self._episodes)
        if ended:
            self._last_curve = (
                float(np.mean([e[0] for e in ended])),
                float(np.mean([e[1] for e in ended])),
            )
        elif not self._episodes:
            self._last_curve = (
                float(self._running_return.mean()),
                float(self._running_length.mean()),
            )
        return {
            "step": self.steps,
            "episode_return": self._last_curve[0],
            "episode_length": self._last_curve[1],
            "episodes_finished": len(ended),
        }

    def episodes(self, limit: int) -> dict[str, Any]:
        """The ``limit`` most recent episodes, oldest first, as in ``TrainResult.metrics``."""
        recent = self._episodes[-limit:]
        return {
            "return": np.asarray([e[0] for e in recent], np.float32),
            "length": np.asarray([e[1] for e in recent], np.int32),
            "context_id": np.asarray([e[2] for e in recent], np.int32),
            "step": np.asarray([e[3] for e in recent], np.int32),
            "total": len(self._episodes),
        }

    def evaluate(self, act, params, episodes: int, key) -> np.ndarray:
        """Mean undiscounted return of each copy's first ``episodes`` episodes under
        ``act(params, obs, context_input, key) -> env actions`` (copies that are done keep stepping
        until the last one finishes; their later episodes are not counted)."""
        returns = [[] for _ in range(self.num_envs)]
        running = np.zeros(self.num_envs)
        while min(len(r) for r in returns) < episodes:
            key, action_key = jax.random.split(key)
            step = self.step(np.asarray(act(params, self.obs, self.context, action_key)))
            running += step.reward
            for i in np.flatnonzero(step.done):
                returns[i].append(running[i])
            running[step.done] = 0.0
        return np.asarray([np.mean(r[:episodes]) for r in returns])

    def close(self) -> None:
        self.envs.close()

    def __enter__(self) -> HostCollector:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
