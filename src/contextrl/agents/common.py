"""What every agent shares: the config fields, what networks are built from, the policy type, the
contextual environment, episode bookkeeping and progress.

Episode bookkeeping lives inside the compiled loop: running returns per environment copy, a ring
buffer of the most recent episodes (return, length, context id, the global step at which it ended)
and per-period aggregates (mean return overall and per context id) that become the training curve.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.agents.networks import (
    ContextInput,
    check_hidden_sizes,
    check_variant,
    context_input,
)
from contextrl.agents.validation import ConfigError, check_fraction, check_positive
from contextrl.context.features import ContextBase, ContextSpace
from contextrl.context.selectors import FromSet, make_selector
from contextrl.core.contextual import ContextualEnv, make_provider
from contextrl.core.env import MAX_STEP_COUNT, Env
from contextrl.core.host import HostEnv


@dataclasses.dataclass(frozen=True)
class AgentConfig:
    """The fields and checks every agent's config shares; an agent's config adds its own (and may
    change a default by declaring the field again)."""

    total_timesteps: int = 100_000
    """Environment steps over all copies, warm-up included; rounded down to whole metrics rows."""
    num_envs: int = 4
    """Environment copies stepped in parallel."""
    gamma: float = 0.99
    """Discount factor."""
    hidden_sizes: tuple[int, ...] = (64, 64)
    """Widths of the hidden layers (of each network: actor, critics or Q-network)."""
    activation: str = "tanh"
    """Hidden activation: "tanh" or "relu"."""
    variant: str = "hidden"
    """How the agent sees the context: "hidden", "concat_all", "concat_varying" or "gated"."""
    context_selector: str = "round_robin"
    """How a context set is visited at each reset: "round_robin" (the default everywhere), "random"
    or "static"; copy i of N runs global episodes i, i + N, …"""
    episode_log_size: int = 1000
    """How many of the most recent episodes the result keeps individually."""
    progress_every: int = 0
    """Print a progress line every this many metrics rows (0: silent)."""

    def __post_init__(self):
        if isinstance(self.hidden_sizes, (list, tuple)):  # anything else is refused by validate
            object.__setattr__(self, "hidden_sizes", tuple(self.hidden_sizes))

    # What ``total_timesteps`` is rounded down to, said where the rounding drops steps.
    training_unit: ClassVar[str] = "whole metrics rows"

    @property
    def trained_timesteps(self) -> int:
        """Environment steps training takes: ``total_timesteps`` rounded down to whole units."""
        return self.total_timesteps

    def validate(self) -> None:
        """Raise ConfigError for any value that cannot train."""
        for name in ("total_timesteps", "num_envs", "episode_log_size"):
            check_positive(name, getattr(self, name), integer=True)
        if self.total_timesteps > MAX_STEP_COUNT:
            raise ConfigError(
                f"total_timesteps must be at most {MAX_STEP_COUNT:,} (the training step counter "
                f"is int32), got {self.total_timesteps:,}"
            )
        check_positive("progress_every", self.progress_every, integer=True, allow_zero=True)
        check_fraction("gamma", self.gamma)
        check_hidden_sizes(self.hidden_sizes, self.activation)
        check_variant(self.variant)


def agent_inputs(
    config: AgentConfig, env: Any, train_contexts: Any, agent: str, *, host: bool = True
) -> tuple[Any, Any, ContextInput]:
    """(observation space, action space, context input): all an agent's networks are built from, for
    a JAX environment (refused when it shows its own context) or, where ``host``, a host one."""
    config.validate()
    if not (host and isinstance(env, HostEnv)):
        check_compiled_env(env, agent)
    context = context_input(config.variant, env.context_space, train_contexts)
    return env.base_observation_space, env.action_space, context


@dataclasses.dataclass(frozen=True)
class Policy:
    """An agent's actions: ``act(params, obs, context_vector, key)`` for one observation or a batch
    (host loops call it with the context input they read from gymnasium's ``info``); called as
    ``policy(params, obs, ctx, key)`` it reads the context input from a JAX environment's context."""

    act: Callable
    context: ContextInput
    space: ContextSpace

    def __call__(self, params, obs, ctx, key):
        return self.act(params, obs, self.context.vector(self.space, ctx), key)


def check_compiled_env(env: Any, agent: str) -> None:
    """Refuse all but a contextrl JAX environment (what a compiled training loop steps) whose
    observation the environment itself does not already extend with its context."""
    if not isinstance(env, Env):
        if isinstance(env, HostEnv):
            host_path = (
                f"train it through the gymnasium vector adapter, ppo.train_gymnasium(config, "
                f"{env.name!r}, contexts, key), or pick a JAX environment"
                if agent == "PPO"
                else "pick a JAX environment"
            )
            raise ConfigError(
                f"{env.name} is a host environment (its simulator steps outside JAX) and this "
                f"{agent} training loop is compiled end to end for JAX environments; {host_path}"
            )
        raise ConfigError(
            f"{agent} trains a contextrl environment from crl.make(...); got a {type(env).__name__}"
        )
    if not env.obs_context.hidden:
        raise ConfigError(
            f"{env.name} already appends {list(env.obs_context.features)} to its observation; the "
            f"agent builds its own context input (its variant), so pass the environment without "
            f"obs_context_features"
        )


def contextual_env_factory(
    env: Env, train_contexts: Any, selector: str
) -> Callable[[Any], ContextualEnv]:
    """Validate the training contexts now; return ``contexts -> ContextualEnv`` for use inside train.

    Passing ``None`` uses ``train_contexts``; passing a batch of the same shape (possibly traced, under
    ``vmap`` over specialists) trains on that set instead.
    """
    provider = make_provider(env, train_contexts, selector)
    template = provider.contexts if isinstance(provider, FromSet) else None
    chosen_selector = make_selector(selector)

    def build(contexts: Any) -> ContextualEnv:
        if contexts is None:
            return ContextualEnv(env, provider)
        if template is None:
            raise ConfigError(
                "train(key, contexts): the agent was made with a distribution spec, which is "
                "resampled at every reset; pass a context set to make_train to train on given sets"
            )
        if not isinstance(contexts, ContextBase) or type(contexts) is not type(template):
            raise ConfigError(
                f"train(key, contexts) expects a batch of {type(template).__name__}, got "
                f"{type(contexts).__name__}"
            )
        if contexts.batch_shape != template.batch_shape:
            raise ConfigError(
                f"train(key, contexts): the context set has batch shape {contexts.batch_shape}, but "
                f"make_train was given {template.batch_shape}; vmap over a leading agent axis"
            )
        return ContextualEnv(env, FromSet(contexts, chosen_selector))

    return build


def num_context_ids(env: Env, train_contexts: Any) -> int:
    """How many context ids the training curve tracks (0 when contexts are resampled, id −1)."""
    provider = make_provider(env, train_contexts)
    return provider.size if isinstance(provider, FromSet) else 0


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class EpisodeLog:
    """Running episode returns per copy, a ring buffer of finished episodes, period aggregates."""

    running_return: jax.Array  # (num_envs,)
    running_length: jax.Array  # (num_envs,)
    returns: jax.Array  # (capacity,) ring buffer of finished episodes
    lengths: jax.Array
    context_ids: jax.Array
    end_steps: jax.Array
    finished: jax.Array  # total episodes finished so far
    period_sum: jax.Array  # this period's finished returns, summed
    period_length_sum: jax.Array
    period_count: jax.Array
    context_sum: jax.Array  # (num_contexts,) per context id
    context_count: jax.Array
    last_return: jax.Array  # the latest period's curve values, kept for periods where nothing ended
    last_length: jax.Array
    last_context_return: jax.Array  # (num_contexts,)

    @classmethod
    def create(cls, num_envs: int, capacity: int, num_contexts: int) -> EpisodeLog:
        zeros = jnp.zeros((num_envs,), jnp.float32)
        capacity = max(capacity, num_envs)
        return cls(
            running_return=zeros,
            running_length=jnp.zeros((num_envs,), jnp.int32),
            returns=jnp.full((capacity,), jnp.nan, jnp.float32),
            lengths=jnp.zeros((capacity,), jnp.int32),
            context_ids=jnp.full((capacity,), -2, jnp.int32),
            end_steps=jnp.full((capacity,), -1, jnp.int32),
            finished=jnp.zeros((), jnp.int32),
            period_sum=jnp.zeros((), jnp.float32),
            period_length_sum=jnp.zeros((), jnp.float32),
            period_count=jnp.zeros((), jnp.int32),
            context_sum=jnp.zeros((num_contexts,), jnp.float32),
            context_count=jnp.zeros((num_contexts,), jnp.int32),
            last_return=jnp.zeros((), jnp.float32),
            last_length=jnp.zeros((), jnp.float32),
            last_context_return=jnp.full((num_contexts,), jnp.nan, jnp.float32),
        )

    def record(self, reward, done, context_id, step) -> EpisodeLog:
        """Add one vector step: rewards, episode ends and the context id each reward belongs to."""
        episode_return = self.running_return + reward
        episode_length = self.running_length + 1
        capacity = self.returns.shape[0]
        order = jnp.cumsum(done.astype(jnp.int32)) - 1
        slot = jnp.where(done, (self.finished + order) % capacity, capacity)  # capacity: dropped
        done_f = done.astype(jnp.float32)
        num_contexts = self.context_sum.shape[0]
        context_slot = jnp.where(done & (context_id >= 0), context_id, num_contexts)
        return dataclasses.replace(
            self,
            running_return=jnp.where(done, 0.0, episode_return),
            running_length=jnp.where(done, 0, episode_length),
            returns=self.returns.at[slot].set(episode_return, mode="drop"),
            lengths=self.lengths.at[slot].set(episode_length, mode="drop"),
            context_ids=self.context_ids.at[slot].set(context_id, mode="drop"),
            end_steps=self.end_steps.at[slot].set(jnp.broadcast_to(step, done.shape), mode="drop"),
            finished=self.finished + done.sum(dtype=jnp.int32),
            period_sum=self.period_sum + (episode_return * done_f).sum(),
            period_length_sum=self.period_length_sum + (episode_length * done_f).sum(),
            period_count=self.period_count + done.sum(dtype=jnp.int32),
            context_sum=self.context_sum.at[context_slot].add(episode_return, mode="drop"),
            context_count=self.context_count.at[context_slot].add(1, mode="drop"),
        )

    def close_row(
        self, period: jax.Array, step: jax.Array, progress: Progress
    ) -> tuple[EpisodeLog, dict[str, jax.Array]]:
        """:meth:`close_period`'s row stamped with the agent's ``step`` count and reported to
        ``progress``: how every compiled training loop ends a metrics period."""
        log, row = self.close_period()
        row["step"] = step
        progress.report(period, step, row["episode_return"])
        return log, row

    def close_period(self) -> tuple[EpisodeLog, dict[str, jax.Array]]:
        """This period's curve row and a log with the period cleared.

        ``episode_return``/``episode_length`` average the episodes that ended in the period; when
        none did, they repeat the last period's values, and before any episode has ended they are the
        running (unfinished) episodes' mean so far, a lower bound for non-negative rewards: never NaN.
        ``context_return`` per context id repeats its last value likewise and is NaN (masked) only
        until that context's first episode ends.
        """
        count = self.period_count
        started = self.finished > 0
        fallback_return = jnp.where(started, self.last_return, self.running_return.mean())
        fallback_length = jnp.where(
            started, self.last_length, self.running_length.astype(jnp.float32).mean()
        )
        episode_return = jnp.where(
            count > 0, self.period_sum / jnp.maximum(count, 1), fallback_return
        )
        episode_length = jnp.where(
            count > 0, self.period_length_sum / jnp.maximum(count, 1), fallback_length
        )
        context_return = jnp.where(
            self.context_count > 0,
            self.context_sum / jnp.maximum(self.context_count, 1),
            self.last_context_return,
        )
        row = {
            "episode_return": episode_return,
            "episode_length": episode_length,
            "episodes_finished": count,
            "context_return": context_return,
        }
        cleared = dataclasses.replace(
            self,
            period_sum=jnp.zeros_like(self.period_sum),
            period_length_sum=jnp.zeros_like(self.period_length_sum),
            period_count=jnp.zeros_like(self.period_count),
            context_sum=jnp.zeros_like(self.context_sum),
            context_count=jnp.zeros_like(self.context_count),
            last_return=jnp.where(count > 0, episode_return, self.last_return),
            last_length=jnp.where(count > 0, episode_length, self.last_length),
            last_context_return=context_return,
        )
        return cleared, row

    def episodes(self) -> dict[str, jax.Array]:
        """The ring buffer in chronological order (oldest first); unused slots have context id −2."""
        capacity = self.returns.shape[0]
        start = jnp.where(self.finished > capacity, self.finished % capacity, 0)
        order = (start + jnp.arange(capacity)) % capacity
        return {
            "return": self.returns[order],
            "length": self.lengths[order],
            "context_id": self.context_ids[order],
            "step": self.end_steps[order],
            "total": self.finished,
        }


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TrainResult:
    """Trained parameters and training metrics (arrays; a leading axis per vmapped seed or agent).

    ``metrics`` holds one row per logging period (an update for PPO): ``step`` (environment steps so
    far), ``episode_return``/``episode_length`` (mean over episodes that ended in the period; the
    previous period's value when none did, see :meth:`EpisodeLog.close_period`), ``episodes_finished``, ``context_return`` (per context id of the training set), the
    algorithm's losses; and ``episodes``, the most recent individual episodes: ``return``, ``length``,
    ``context_id`` (−1: resampled), ``step`` at which it ended, ``total`` number finished.
    """

    params: Any
    metrics: dict


class Progress:
    """Periodic lines (steps done, steps/s, recent return) printed from inside a compiled loop.

    The loop calls back to the host once per period; the host prints every ``every``-th. Under ``vmap``
    over seeds the host is called once per seed with the same step; only the first is printed.
    """

    def __init__(self, name: str, total_steps: int, every: int):
        self.name = name
        self.total_steps = total_steps
        self.every = every
        self.start: tuple[float, int] | None = None
        self.last_step = -1

    def __call__(self, period, step, episode_return) -> None:
        period, step = int(np.max(period)), int(np.max(step))
        if step == self.last_step:
            return
        now = time.perf_counter()
        if self.start is None or step < self.last_step:
            self.start = (now, step)
        self.last_step = step
        if (period + 1) % self.every:
            return
        elapsed = now - self.start[0]
        rate = (step - self.start[1]) / elapsed if elapsed > 0 else float("nan")
        values = np.asarray(episode_return, np.float64)
        recent = float(np.nanmean(values)) if np.any(np.isfinite(values)) else float("nan")
        print(
            f"[{self.name}] step {step:>10,}/{self.total_steps:,}  {rate:>10,.0f} steps/s  "
            f"recent return {recent:9.2f}",
            flush=True,
        )

    def report(self, period: jax.Array, step: jax.Array, episode_return: jax.Array) -> None:
        """Call inside the loop once per period; does nothing when progress is off (``every`` 0)."""
        if self.every > 0:
            jax.debug.callback(self, period, step, episode_return)


def anneal(initial: float, total_updates: int, enabled: bool) -> Callable | float:
    """A linearly decaying learning rate over ``total_updates`` optimiser steps, or a constant."""
    if not enabled:
        return initial

    def schedule(count):
        return initial * (1.0 - jnp.minimum(count, total_updates) / total_updates)

    return schedule
