"""One host stepping loop for every agent: N copies of a registered environment through gymnasium's
public vector API, for environments that are not JAX functions (dm_control, Box2D, RNA…).

    collector = HostCollector("DmcWalker", num_envs=4, contexts=contexts, variant="concat_all")
    step = collector.step(env_actions)      # obs, context input, rewards, ends, final observations

The collector owns what every agent's host training needs and nothing algorithm-specific: the vector
env (``gymnasium.make_vec("contextrl/<Id>-v0", num_envs=N, contexts=...)``, same-step auto-reset, its
copies stepped in slices on every core once there are enough of them; ``num_workers=`` sets it), the
agent's context input read from ``info["context"]`` and normalised by the feature bounds as on the JAX
path, and the episode bookkeeping behind training curves (the JAX path's :class:`EpisodeLog`).
:func:`train_on_host` is the one training loop over it (warm-up, rows of updates, metrics, progress);
an agent adds only a :class:`HostLearner` (acting, storing and learning).
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import gymnasium
import jax
import numpy as np

from contextrl.agents.common import EpisodeLog, Progress, TrainResult
from contextrl.agents.networks import ContextInput, context_input
from contextrl.agents.validation import ConfigError
from contextrl.context.distributions import DISTRIBUTIONS
from contextrl.context.schedule import resolve_contexts
from contextrl.gymnasium.registration import gym_id


@jax.tree_util.register_dataclass
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


@jax.jit
def _record_steps(log: EpisodeLog, rewards, dones, context_ids, steps) -> EpisodeLog:
    """``log`` with buffered vector steps added in order: one compiled call per metrics row instead
    of one per step (a call costs about as much as stepping CartPole's copies)."""
    return jax.lax.scan(
        lambda log, step: (log.record(*step), None), log, (rewards, dones, context_ids, steps)
    )[0]


_close_period = jax.jit(EpisodeLog.close_period)
_FLUSH_EVERY = 4096  # vector steps buffered at most before they go into the log


class HostCollector:
    """N copies of ``env_id`` stepped on the host, with context input and episode bookkeeping."""

    def __init__(
        self,
        env_id: str,
        num_envs: int,
        contexts: Any,
        variant: str = "hidden",
        *,
        selector: str = "random",
        seed: int = 0,
        vectorization: str = "async",
        context: ContextInput | None = None,
        episode_log_size: int = 1000,
        **env_kwargs: Any,
    ):
        """``context`` fixes the agent's context input (an agent trained on other contexts sees
        the features it was trained with); by default it follows ``variant`` and ``contexts``.
        Episodes are logged by their index in the context set (−1: resampled), as on the JAX path."""
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
            context = context_input(variant, self.space, contexts)
        self.context_input = context
        self._names = context.view.features
        self.steps = 0
        ids = resolve_contexts(self.space, contexts).ids
        self._set_index = {user_id: index for index, user_id in enumerate(ids)}
        self._log = EpisodeLog.create(num_envs, episode_log_size, len(ids))
        self._pending: list[tuple] = []  # (reward, done, context id, step) not yet in the log
        obs, info = self.envs.reset(seed=seed)
        self.obs, self.context = np.asarray(obs, np.float32), self._context_input(info)

    @property
    def agent_inputs(self) -> tuple[Any, Any, ContextInput]:
        """(observation space, action space, context input) of one copy: what agents build from."""
        return self.envs.single_observation_space, self.envs.single_action_space, self.context_input

    def _context_input(self, info) -> np.ndarray:
        columns = []
        for name in self._names:
            values = np.asarray(info["context"][name])
            if values.dtype == object:  # categorical features arrive as choice names
                values = np.array([self.space.features[name].choices.index(v) for v in values])
            columns.append(values.astype(np.float32))
        if not columns:
            return np.zeros((self.num_envs, 0), np.float32)
        return np.asarray(
            self.context_input.view.normalized(self.space, np.stack(columns, axis=-1))
        )

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
        context_id = np.full(self.num_envs, -1, np.int32)
        for i in np.flatnonzero(done):
            context_id[i] = self._set_index.get(info["final_info"]["context_id"][i], -1)
        self._pending.append((reward, done, context_id, self.steps))
        if len(self._pending) == _FLUSH_EVERY:
            self._flush()
        self.obs, self.context = obs, self._context_input(info)
        return HostStep(reward, terminated, truncated, final, obs, self.context)

    def _flush(self) -> None:
        if self._pending:
            columns = [np.stack(column) for column in zip(*self._pending, strict=True)]
            self._log = _record_steps(self._log, *columns)
            self._pending = []

    def close_period(self) -> dict[str, Any]:
        """The training-curve row of the episodes that ended since the last call (see
        :meth:`EpisodeLog.close_period`: never NaN) and the steps so far."""
        self._flush()
        self._log, row = _close_period(self._log)
        return {"step": self.steps, **jax.device_get(row)}

    def episodes(self) -> dict[str, Any]:
        """The most recent episodes (up to the log's size), oldest first, as in
        ``TrainResult.metrics``."""
        self._flush()
        episodes = jax.device_get(self._log.episodes())
        kept = min(int(episodes["total"]), len(episodes["return"]))
        return {name: v if name == "total" else v[:kept] for name, v in episodes.items()}

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


@dataclasses.dataclass(frozen=True)
class HostSchedule:
    """How the host loop interleaves stepping and learning: ``warmup_steps`` vector steps of the
    learner's warm-up actions, then ``num_rows`` metrics rows of ``updates_per_row`` updates, each after
    ``steps_per_update`` vector steps."""

    warmup_steps: int
    num_rows: int
    updates_per_row: int
    steps_per_update: int

    @property
    def total_steps(self) -> int:
        return self.warmup_steps + self.num_rows * self.updates_per_row * self.steps_per_update


class HostLearner(abc.ABC):
    """An agent's part of host training; :func:`train_on_host` steps the environment around it.
    It is made by ``(config, collector, key, init_params)``: ``init_params`` None for fresh parameters.

    Per vector step the loop calls ``act`` for the collector's current observation and context input,
    steps every copy with the returned environment actions, and hands the step to ``store``; after
    every ``steps_per_update`` steps it calls ``update``, and at the end of each metrics row
    ``row_metrics``. During the warm-up ``warmup`` is True and ``update`` is not called. A learner
    may learn inside ``store`` instead (SAC) and leave ``update`` empty.
    """

    params: Any
    """The parameters the result returns."""

    @abc.abstractmethod
    def act(self, obs: np.ndarray, context: np.ndarray, warmup: bool) -> np.ndarray:
        """Environment actions for every copy (the learner remembers what it needs to store)."""

    @abc.abstractmethod
    def store(self, obs: np.ndarray, context: np.ndarray, step: HostStep, warmup: bool) -> None:
        """Take in the vector step that followed the last ``act`` from ``obs``/``context``."""

    @abc.abstractmethod
    def update(self) -> None:
        """Learn from what was stored since the last update."""

    @abc.abstractmethod
    def row_metrics(self) -> dict[str, float]:
        """The algorithm's columns of the metrics row that ends now (losses…)."""


def train_on_host(
    name: str,
    config: Any,
    env_id: str,
    train_contexts: Any,
    key,
    make_learner: Callable[[Any, HostCollector, Any, Any], HostLearner],
    schedule: HostSchedule,
    *,
    seed: int = 0,
    vectorization: str = "async",
    init_params: Any = None,
    **env_kwargs: Any,
) -> TrainResult:
    """Train ``make_learner(config, collector, key, init_params)`` by ``schedule`` on
    ``config.num_envs`` copies of ``env_id`` (contexts from ``train_contexts`` by
    ``config.context_selector``): the host training loop of every agent. ``init_params`` continues
    training given parameters (population-based tuning) with a fresh optimiser, replay and warm-up,
    as the JAX path does; None starts from fresh ones.
    Returns the ``TrainResult`` of the agent's JAX path: one metrics row per period (``step``,
    ``episode_return``, ``episode_length``, ``episodes_finished`` and the learner's columns) and the
    most recent ``config.episode_log_size`` episodes."""
    config.validate()
    if config.context_selector == "static" or not isinstance(env_id, str):
        raise ConfigError("train_gymnasium takes a registered env id and a non-static selector")
    with HostCollector(
        env_id,
        config.num_envs,
        train_contexts,
        config.variant,
        selector=config.context_selector,
        seed=seed,
        vectorization=vectorization,
        episode_log_size=config.episode_log_size,
        **env_kwargs,
    ) as collector:
        learner = make_learner(config, collector, key, init_params)

        def vector_step(warmup: bool) -> None:
            obs, context = collector.obs, collector.context
            step = collector.step(learner.act(obs, context, warmup))
            learner.store(obs, context, step, warmup)

        for _ in range(schedule.warmup_steps):
            vector_step(warmup=True)
        collector.close_period()  # warm-up episodes stay in the episode list, not the curve
        progress = Progress(
            f"{name} host", schedule.total_steps * collector.num_envs, config.progress_every
        )
        rows = []
        for row_index in range(schedule.num_rows):
            for _ in range(schedule.updates_per_row):
                for _ in range(schedule.steps_per_update):
                    vector_step(warmup=False)
                learner.update()
            rows.append({**collector.close_period(), **learner.row_metrics()})
            if config.progress_every:
                progress(row_index, rows[-1]["step"], rows[-1]["episode_return"])
        metrics = {column: np.asarray([row[column] for row in rows]) for column in rows[0]}
        metrics["episodes"] = collector.episodes()
        return TrainResult(learner.params, metrics)
