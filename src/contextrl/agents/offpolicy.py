"""The compiled off-policy loop DQN/C51 and SAC share, as brax's agents share their acting code.

A run is one JAX function: a warm-up of random actions that fills the replay buffer, then rows of
updates, each update the algorithm's own mix of vector steps and gradient steps (DQN: ``train_frequency``
steps, one gradient step; SAC: ``policy_frequency`` rounds of a step and a critic update, one actor
update); each logging period is one metrics row. The host loop (:mod:`contextrl.agents.host`) follows
the same schedule, :attr:`OffPolicyConfig.schedule`. Under a curriculum the logging period is its
rollout: the period's steps draw from its current distribution, and it is told the period's returns
(and, for SPaCE, the learner's values of the pool's start states) before the next.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple

import jax
import jax.numpy as jnp

from contextrl.agents.common import (
    AgentConfig,
    EpisodeLog,
    Progress,
    TrainResult,
    contextual_env_factory,
    num_context_ids,
)
from contextrl.agents.curricula import (
    check_curriculum,
    curriculum_env,
    curriculum_of,
    feedback,
    refuse_contexts,
)
from contextrl.agents.host import HostSchedule
from contextrl.agents.networks import ContextInput
from contextrl.agents.replay import Replay, transition, transition_example
from contextrl.agents.validation import ConfigError, check_fraction, check_positive


@dataclasses.dataclass(frozen=True)
class OffPolicyConfig(AgentConfig):
    """The schedule, replay capacity and replay checks of an off-policy agent. A subclass declares the
    fields ``buffer_size``, ``batch_size``, ``n_step``, ``tau``, ``learning_starts`` and ``log_every``
    and the property ``steps_per_update`` (vector steps per update)."""

    @property
    def steps_per_update(self) -> int:
        raise NotImplementedError

    def validate(self) -> None:
        """Raise ConfigError for a replay or schedule setting that cannot train."""
        super().validate()
        for name in ("buffer_size", "batch_size", "n_step", "log_every"):
            check_positive(name, getattr(self, name), integer=True)
        check_positive("learning_starts", self.learning_starts, integer=True, allow_zero=True)
        check_fraction("tau", self.tau)
        if self.tau == 0:
            raise ConfigError("tau must be > 0 (0 would never update the target network)")
        if self.buffer_size < self.num_envs * max(self.n_step, 2):
            raise ConfigError(
                f"buffer_size ({self.buffer_size}) must hold at least n_step vector steps "
                f"({self.num_envs} × {max(self.n_step, 2)})"
            )

    def check_schedule(self) -> None:
        """Refuse a budget that leaves no full logging period after the warm-up (checked after the
        subclass's own fields, which the schedule reads)."""
        if self.num_rows < 1:
            warmup = self.warmup_steps * self.num_envs
            period = self.num_envs * self.steps_per_update * self.updates_per_row
            raise ConfigError(
                f"total_timesteps ({self.total_timesteps}) leaves no full logging period after the "
                f"warm-up ({warmup} transitions; log_every {self.log_every}); the smallest budget "
                f"that trains is {warmup + period} (or lower learning_starts or log_every)"
            )

    @property
    def warmup_steps(self) -> int:
        """Vector steps of random actions before learning (at least n_step, to sample from)."""
        return max(-(-self.learning_starts // self.num_envs), self.n_step)

    @property
    def updates_per_row(self) -> int:
        return max(1, self.log_every // (self.num_envs * self.steps_per_update))

    @property
    def num_rows(self) -> int:
        remaining = self.total_timesteps - self.warmup_steps * self.num_envs
        per_row = self.num_envs * self.steps_per_update * self.updates_per_row
        return max(remaining, 0) // per_row

    training_unit: ClassVar[str] = "the warm-up, then whole logging periods"

    @property
    def num_updates(self) -> int:
        return self.num_rows * self.updates_per_row

    @property
    def trained_timesteps(self) -> int:
        return (self.warmup_steps + self.num_updates * self.steps_per_update) * self.num_envs

    @property
    def replay_capacity(self) -> int:
        """Vector steps the replay buffer holds (at least one n-step return's worth)."""
        return max(self.buffer_size // self.num_envs, self.n_step + 1)

    @property
    def schedule(self) -> HostSchedule:
        """The same schedule for the host loop."""
        return HostSchedule(
            self.warmup_steps, self.num_rows, self.updates_per_row, self.steps_per_update
        )


class World(NamedTuple):
    """What the loop threads through every step: the copies, their observation, the replay buffer,
    the episode log, the environment steps so far and the key."""

    env_state: Any
    obs: jax.Array
    replay: Replay
    log: EpisodeLog
    step: jax.Array
    key: jax.Array


# ``step(world, action_fn) -> world``: one vector step with the actions ``action_fn(obs, context, key)``
Step = Callable[[World, Callable], World]


@dataclasses.dataclass(frozen=True)
class Algorithm:
    """An off-policy learner as the loop calls it.

    ``init(key, params)`` gives the learner state, a tuple whose first item is the parameters (given
    ``params`` are continued, as population-based tuning does). ``update(learner, world, step,
    update_index)`` runs one update and returns ``(learner, world, metrics)``; ``row_metrics`` turns a
    row's stacked update metrics into the row's entries.
    """

    name: str
    context: ContextInput
    action_example: jax.Array  # one vector step's actions: shape and dtype
    random_action: Callable[[jax.Array], jax.Array]  # the warm-up's, from a key
    to_env: Callable[[jax.Array], jax.Array]  # a stored action as the environment takes it
    init: Callable[[jax.Array, Any], tuple]
    update: Callable[[tuple, World, Step, jax.Array], tuple[tuple, World, Any]]
    row_metrics: Callable[[Any], dict[str, jax.Array]]
    # ``value(params, obs, context_vector)``: the learner's value of a state (SPaCE's signal)
    value: Callable[[Any, jax.Array, jax.Array], jax.Array]


def make_train(
    config: OffPolicyConfig, env, train_contexts: Any, algorithm: Algorithm
) -> Callable[..., TrainResult]:
    """``train(key, contexts=None, params=None) -> TrainResult`` (pure, jittable) of ``algorithm``;
    ``train_contexts`` may be a curriculum that needs no per-step scores (SPaCE, ADR)."""
    curriculum = curriculum_of(train_contexts)
    if curriculum:
        check_curriculum(curriculum, env, algorithm.name, gives_scores=False)
        num_contexts = curriculum.num_ids
    else:
        build_env = contextual_env_factory(env, train_contexts, config.context_selector)
        num_contexts = num_context_ids(env, train_contexts)
    space = env.context_space
    num_envs = config.num_envs
    progress = Progress(algorithm.name, config.trained_timesteps, config.progress_every)

    def train(key, contexts: Any = None, params: Any = None) -> TrainResult:
        refuse_contexts(curriculum, contexts)
        schedule = curriculum.init() if curriculum else None
        cenv = curriculum_env(env, curriculum, schedule) if curriculum else build_env(contexts)
        key, init_key, reset_key = jax.random.split(key, 3)
        learner = algorithm.init(init_key, params)
        env_state, timestep = cenv.reset_copies(reset_key, num_envs)
        context_of = jax.vmap(lambda ctx: algorithm.context.vector(space, ctx))
        example = algorithm.action_example
        replay = Replay.create(
            config.replay_capacity,
            transition_example(timestep.obs, context_of(env_state.context), example),
        )
        log = EpisodeLog.create(num_envs, config.episode_log_size, num_contexts)

        def stepper(cenv) -> Step:
            def step(world: World, action_fn) -> World:
                key, action_key = jax.random.split(world.key)
                context_vector = context_of(world.env_state.context)
                action = action_fn(world.obs, context_vector, action_key).astype(example.dtype)
                env_state, timestep = cenv.step_copies(world.env_state, algorithm.to_env(action))
                steps = world.step + num_envs
                replay = world.replay.add(transition(world.obs, context_vector, action, timestep))
                log = world.log.record(
                    timestep.reward, timestep.done, timestep.info["context_id"], steps
                )
                return World(env_state, timestep.obs, replay, log, steps, key)

            return step

        warmup_step = stepper(cenv)

        def random_step(world, _):
            return warmup_step(world, lambda obs, context, key: algorithm.random_action(key)), None

        world = World(env_state, timestep.obs, replay, log, jnp.zeros((), jnp.int32), key)
        world = jax.lax.scan(random_step, world, None, config.warmup_steps)[0]
        log, _ = (
            world.log.close_period()
        )  # warm-up episodes stay in the episode list, not the curve
        world = world._replace(log=log)

        def row(carry, row_index):
            learner, world, schedule = carry
            step = stepper(curriculum_env(env, curriculum, schedule) if curriculum else cenv)

            def update(carry, update_index):
                learner, world, metrics = algorithm.update(*carry, step, update_index)
                return (learner, world), metrics

            first = row_index * config.updates_per_row
            (learner, world), metrics = jax.lax.scan(
                update, (learner, world), first + jnp.arange(config.updates_per_row)
            )
            if curriculum:
                told = feedback(
                    curriculum,
                    env,
                    algorithm.context,
                    algorithm.value,
                    learner[0],
                    world.log,
                    reset_key,
                )
                trace = curriculum.trace(schedule)
                schedule = curriculum.update(schedule, told)
            log, row = world.log.close_row(row_index, world.step, progress)
            row = {**row, **algorithm.row_metrics(metrics)}
            if curriculum:
                row["curriculum"] = trace
            return (learner, world._replace(log=log), schedule), row

        (learner, world, _), metrics = jax.lax.scan(
            row, (learner, world, schedule), jnp.arange(config.num_rows)
        )
        return TrainResult(learner[0], {**metrics, "episodes": world.log.episodes()})

    return train
