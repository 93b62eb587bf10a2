"""Proximal Policy Optimisation (clipped objective, GAE), the whole training run one JAX function.

    config = ppo.PPOConfig(total_timesteps=500_000, variant="concat_varying")
    train = ppo.make_train(config, env, train_contexts)
    result = jax.jit(train)(key)                          # one seed
    results = jax.jit(jax.vmap(train))(keys)              # many seeds in one call
    specialists = jax.jit(jax.vmap(train))(keys, sets)    # one agent per context set (leading axis)

``train(key, contexts=None, params=None)``: with ``contexts`` omitted the agent trains on the
``train_contexts`` given to ``make_train``; a batch of the same shape trains on that set instead, which
is how ``vmap`` trains specialists. ``params`` continues training given parameters (fresh optimiser).
Actions are discrete (categorical) or continuous (a diagonal Gaussian, clipped to the action bounds
when stepping). Episodes cut by the time limit bootstrap from the value of the final
observation instead of counting as failures.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import optax

from contextrl.agents.common import (
    AgentConfig,
    EpisodeLog,
    Policy,
    Progress,
    TrainResult,
    agent_inputs,
    anneal,
    contextual_env_factory,
    num_context_ids,
)
from contextrl.agents.curricula import (
    check_curriculum,
    curriculum_env,
    curriculum_of,
    feedback,
    refuse_contexts,
    seen_contexts,
)
from contextrl.agents.host import HostLearner, HostSchedule, train_on_host
from contextrl.agents.networks import ConditionedMLP, ContextInput
from contextrl.agents.validation import (
    ConfigError,
    check_fraction,
    check_positive,
    flat_observation_size,
)


@dataclasses.dataclass(frozen=True)
class PPOConfig(AgentConfig):
    """PPO hyper-parameters (defaults: PureJaxRL's CartPole settings); one metrics row per update."""

    total_timesteps: int = 500_000
    num_steps: int = 128
    """Steps per copy in each rollout (one update per rollout)."""
    learning_rate: float = 2.5e-4
    """Adam step size."""
    anneal_lr: bool = True
    """Decay the learning rate linearly to zero over training."""
    gae_lambda: float = 0.95
    """GAE trace parameter."""
    num_minibatches: int = 4
    """Minibatches per epoch; must divide num_envs × num_steps."""
    update_epochs: int = 4
    """Passes over each rollout."""
    clip_eps: float = 0.2
    """Clip range of the policy ratio and (with ``clip_value``) of the value change."""
    clip_value: bool = True
    """Clip the value change to ``clip_eps`` as PureJaxRL and CleanRL do (Stable-Baselines3 does not)."""
    ent_coef: float = 0.01
    """Weight of the entropy bonus."""
    vf_coef: float = 0.5
    """Weight of the value loss."""
    max_grad_norm: float = 0.5
    """Global gradient-norm clip."""
    log_std_init: float = 0.0
    """Initial log standard deviation of the Gaussian policy (continuous actions)."""

    def validate(self) -> None:
        """Raise ConfigError for any value that cannot train."""
        super().validate()
        for name in ("num_steps", "num_minibatches", "update_epochs"):
            check_positive(name, getattr(self, name), integer=True)
        for name in ("learning_rate", "max_grad_norm"):
            check_positive(name, getattr(self, name))
        for name in ("clip_eps", "ent_coef", "vf_coef"):
            check_positive(name, getattr(self, name), allow_zero=True)
        check_fraction("gae_lambda", self.gae_lambda)
        for name in ("anneal_lr", "clip_value"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"{name} must be True or False, got {getattr(self, name)!r}")
        if not isinstance(self.log_std_init, (int, float)) or not np.isfinite(self.log_std_init):
            raise ConfigError(f"log_std_init must be a finite number, got {self.log_std_init!r}")
        batch = self.num_envs * self.num_steps
        if batch % self.num_minibatches:
            raise ConfigError(
                f"num_minibatches ({self.num_minibatches}) must divide num_envs × num_steps ({batch})"
            )
        if self.total_timesteps < batch:
            raise ConfigError(
                f"total_timesteps ({self.total_timesteps}) is less than one rollout "
                f"(num_envs × num_steps = {batch})"
            )

    training_unit: ClassVar[str] = "whole rollouts of num_envs × num_steps"

    @property
    def num_updates(self) -> int:
        return self.total_timesteps // (self.num_envs * self.num_steps)

    @property
    def trained_timesteps(self) -> int:
        return self.num_updates * self.num_envs * self.num_steps


@dataclasses.dataclass(frozen=True)
class _Networks:
    actor: ConditionedMLP
    critic: ConditionedMLP
    context: ContextInput
    discrete: bool
    action_low: np.ndarray | None
    action_high: np.ndarray | None


def _networks(
    config: PPOConfig, observation_space, action_space, context: ContextInput
) -> _Networks:
    """Actor and critic for these spaces (contextrl's or gymnasium's) and context input."""
    if hasattr(action_space, "n"):
        discrete, action_size, low, high = True, int(action_space.n), None, None
    elif hasattr(action_space, "low") and len(action_space.shape) == 1:
        discrete, action_size = False, action_space.shape[0]
        low, high = np.asarray(action_space.low), np.asarray(action_space.high)
    else:
        raise ConfigError(f"PPO needs a Discrete or a 1-D Box action space, got {action_space!r}")
    obs_size = flat_observation_size("PPO", observation_space)
    common = dict(hidden_sizes=config.hidden_sizes, context=context, activation=config.activation)
    actor = ConditionedMLP(obs_size, action_size, out_scale=0.01, **common)
    critic = ConditionedMLP(obs_size, 1, out_scale=1.0, **common)
    return _Networks(actor, critic, context, discrete, low, high)


def _policy_outputs(nets: _Networks, params, obs, context_vector):
    """Logits (discrete) or (mean, log_std) (continuous)."""
    out = nets.actor.apply(params["actor"], obs, context_vector)
    if nets.discrete:
        return out, None
    return out, jnp.broadcast_to(params["log_std"], out.shape)


def _sample(nets: _Networks, params, obs, context_vector, key):
    """An action, its log-probability."""
    head, log_std = _policy_outputs(nets, params, obs, context_vector)
    if nets.discrete:
        action = jax.random.categorical(key, head)
        log_prob = jnp.take_along_axis(
            jax.nn.log_softmax(head), action[..., None], axis=-1
        ).squeeze(-1)
        return action, log_prob
    action = head + jnp.exp(log_std) * jax.random.normal(key, head.shape)
    return action, _gaussian_log_prob(head, log_std, action)


def _gaussian_log_prob(mean, log_std, x):
    z = (x - mean) / jnp.exp(log_std)
    return jnp.sum(-0.5 * z**2 - log_std - 0.5 * jnp.log(2 * jnp.pi), axis=-1)


def _log_prob_entropy(nets: _Networks, params, obs, context_vector, action):
    head, log_std = _policy_outputs(nets, params, obs, context_vector)
    if nets.discrete:
        log_probs = jax.nn.log_softmax(head)
        log_prob = jnp.take_along_axis(log_probs, action[..., None], axis=-1).squeeze(-1)
        entropy = -jnp.sum(jnp.exp(log_probs) * log_probs, axis=-1)
        return log_prob, entropy
    entropy = jnp.sum(log_std + 0.5 * jnp.log(2 * jnp.pi * jnp.e), axis=-1)
    return _gaussian_log_prob(head, log_std, action), entropy


def _env_action(nets: _Networks, action):
    if nets.discrete:
        return action
    low = jnp.asarray(np.where(np.isfinite(nets.action_low), nets.action_low, -np.inf))
    high = jnp.asarray(np.where(np.isfinite(nets.action_high), nets.action_high, np.inf))
    return jnp.clip(action, low, high)


def _init_params(nets: _Networks, config: PPOConfig, key) -> dict:
    actor_key, critic_key = jax.random.split(key)
    params = {"actor": nets.actor.init(actor_key), "critic": nets.critic.init(critic_key)}
    if not nets.discrete:
        params["log_std"] = jnp.full((nets.actor.out_size,), config.log_std_init, jnp.float32)
    return params


def init_params(config: PPOConfig, env, train_contexts: Any, key) -> dict:
    """Freshly initialised parameters (what ``train`` starts from for the same key's split)."""
    return _init_params(
        _networks(config, *agent_inputs(config, env, train_contexts, "PPO")), config, key
    )


def _time_limit_reward(value, params, step, context_vector, gamma):
    """The step's reward plus, where the time limit cut the episode (not a failure), the discounted
    value of its final observation."""
    cut = step.truncated & ~step.terminated
    return step.reward + gamma * value(params, step.final_obs, context_vector) * cut


def _learner(config: PPOConfig, nets: _Networks):
    """The optimiser, the value function and ``learn``: GAE over a rollout, then clipped-PPO epochs.

    ``learn(params, opt_state, rollout, last_value, key)`` takes a rollout of arrays shaped
    (num_steps, num_envs, ...): observations, context vectors, actions, log-probabilities, values,
    rewards (time-limit cuts already bootstrapped) and episode ends; it also returns the rollout's
    advantages (what a curriculum scores contexts by).
    """
    num_envs, num_steps = config.num_envs, config.num_steps
    minibatch_size = num_envs * num_steps // config.num_minibatches
    optimizer = optax.chain(
        optax.clip_by_global_norm(config.max_grad_norm),
        optax.adam(
            anneal(
                config.learning_rate,
                config.num_updates * config.update_epochs * config.num_minibatches,
                config.anneal_lr,
            ),
            eps=1e-5,
        ),
    )

    def value(params, obs, context_vector):
        return nets.critic.apply(params["critic"], obs, context_vector).squeeze(-1)

    def loss_fn(params, batch):
        obs, context_vector, action, old_log_prob, old_value, advantage, target = batch
        log_prob, entropy = _log_prob_entropy(nets, params, obs, context_vector, action)
        new_value = value(params, obs, context_vector)
        value_error = (new_value - target) ** 2
        if config.clip_value:
            clipped_value = old_value + jnp.clip(
                new_value - old_value, -config.clip_eps, config.clip_eps
            )
            value_error = jnp.maximum(value_error, (clipped_value - target) ** 2)
        value_loss = 0.5 * value_error.mean()
        ratio = jnp.exp(log_prob - old_log_prob)
        advantage = (advantage - advantage.mean()) / (advantage.std() + 1e-8)
        actor_loss = -jnp.minimum(
            ratio * advantage,
            jnp.clip(ratio, 1 - config.clip_eps, 1 + config.clip_eps) * advantage,
        ).mean()
        entropy = entropy.mean()
        total = actor_loss + config.vf_coef * value_loss - config.ent_coef * entropy
        return total, (actor_loss, value_loss, entropy)

    def learn(params, opt_state, rollout, last_value, key):
        observations, context_vectors, actions, log_probs, values, rewards, dones = rollout

        def gae_step(carry, inputs):
            advantage, next_value = carry
            reward, state_value, done = inputs
            not_done = 1.0 - done
            delta = reward + config.gamma * next_value * not_done - state_value
            advantage = delta + config.gamma * config.gae_lambda * not_done * advantage
            return (advantage, state_value), advantage

        _, advantages = jax.lax.scan(
            gae_step,
            (jnp.zeros_like(last_value), last_value),
            (rewards, values, dones.astype(jnp.float32)),
            reverse=True,
        )
        targets = advantages + values
        batch = (observations, context_vectors, actions, log_probs, values, advantages, targets)
        batch = jax.tree_util.tree_map(
            lambda x: x.reshape((num_envs * num_steps,) + x.shape[2:]), batch
        )

        def epoch(carry, _):
            params, opt_state, key = carry
            key, perm_key = jax.random.split(key)
            permutation = jax.random.permutation(perm_key, num_envs * num_steps)
            minibatches = jax.tree_util.tree_map(
                lambda x: x[permutation].reshape(
                    (config.num_minibatches, minibatch_size) + x.shape[1:]
                ),
                batch,
            )

            def minibatch_step(carry, minibatch):
                params, opt_state = carry
                grads, losses = jax.grad(loss_fn, has_aux=True)(params, minibatch)
                updates, opt_state = optimizer.update(grads, opt_state, params)
                return (optax.apply_updates(params, updates), opt_state), losses

            (params, opt_state), losses = jax.lax.scan(
                minibatch_step, (params, opt_state), minibatches
            )
            return (params, opt_state, key), losses

        (params, opt_state, key), losses = jax.lax.scan(
            epoch, (params, opt_state, key), None, config.update_epochs
        )
        return params, opt_state, key, losses, advantages

    return optimizer, value, learn


def make_train(config: PPOConfig, env, train_contexts: Any) -> Callable[..., TrainResult]:
    """Validate everything now and return ``train(key, contexts=None) -> TrainResult`` (pure, jittable).

    ``train_contexts`` takes every form of ``contexts=`` or a curriculum
    (:mod:`contextrl.context.curricula`): then each rollout draws from the curriculum's current
    distribution, the curriculum is updated after each update from the rollout's per-context returns,
    advantages and start values, and ``metrics["curriculum"]`` holds its distribution per update.
    """
    curriculum = curriculum_of(train_contexts)
    nets = _networks(
        config, *agent_inputs(config, env, seen_contexts(train_contexts), "PPO", host=False)
    )
    space = env.context_space
    if curriculum:
        check_curriculum(curriculum, env, "PPO", gives_scores=True)
        num_contexts = curriculum.num_ids
    else:
        build_env = contextual_env_factory(env, train_contexts, config.context_selector)
        num_contexts = num_context_ids(env, train_contexts)
    num_envs, num_steps = config.num_envs, config.num_steps
    num_updates = config.num_updates
    optimizer, value, learn = _learner(config, nets)
    progress = Progress("PPO", num_updates * num_envs * num_steps, config.progress_every)
    context_of = jax.vmap(lambda ctx: nets.context.vector(space, ctx))

    def positive_advantages(advantages, context_ids):
        """Each context id's mean positive advantage over the rollout's steps (PLR's score)."""
        slot = jnp.where(context_ids >= 0, context_ids, num_contexts).ravel()
        positive = jnp.maximum(advantages, 0.0).ravel()
        score_sum = jnp.zeros((num_contexts,)).at[slot].add(positive, mode="drop")
        steps = jnp.zeros((num_contexts,)).at[slot].add(1.0, mode="drop")
        return jnp.where(steps > 0, score_sum / jnp.maximum(steps, 1.0), jnp.nan)

    def train(key, contexts: Any = None, params: Any = None) -> TrainResult:
        refuse_contexts(curriculum, contexts)
        key, init_key, reset_key = jax.random.split(key, 3)
        schedule = curriculum.init() if curriculum else None
        cenv = curriculum_env(env, curriculum, schedule) if curriculum else build_env(contexts)
        if params is None:  # given params: continue training them (population-based tuning)
            params = _init_params(nets, config, init_key)
        opt_state = optimizer.init(params)
        env_state, timestep = cenv.reset_copies(reset_key, num_envs)
        log = EpisodeLog.create(num_envs, config.episode_log_size, num_contexts)

        def env_step(cenv, carry):
            params, env_state, obs, log, step, key = carry
            key, action_key = jax.random.split(key)
            context_vector = context_of(env_state.context)
            action, log_prob = _sample(nets, params, obs, context_vector, action_key)
            state_value = value(params, obs, context_vector)
            context_id = env_state.context_id
            env_state, timestep = cenv.step_copies(env_state, _env_action(nets, action))
            step = step + num_envs
            reward = _time_limit_reward(value, params, timestep, context_vector, config.gamma)
            log = log.record(timestep.reward, timestep.done, timestep.info["context_id"], step)
            transition = (obs, context_vector, action, log_prob, state_value, reward, timestep.done)
            return (params, env_state, timestep.obs, log, step, key), (transition, context_id)

        def update(carry, period):
            params, opt_state, env_state, obs, log, step, key, schedule = carry
            cenv_now = curriculum_env(env, curriculum, schedule) if curriculum else cenv
            (params, env_state, obs, log, step, key), (rollout, context_ids) = jax.lax.scan(
                lambda carry, _: env_step(cenv_now, carry),
                (params, env_state, obs, log, step, key),
                None,
                num_steps,
            )
            last_value = value(params, obs, context_of(env_state.context))
            params, opt_state, key, losses, advantages = learn(
                params, opt_state, rollout, last_value, key
            )
            if curriculum:
                scores = positive_advantages(advantages, context_ids)
                told = feedback(
                    curriculum, env, nets.context, value, params, log, reset_key, scores
                )
                trace = curriculum.trace(schedule)
                schedule = curriculum.update(schedule, told)
            log, row = log.close_row(period, step, progress)
            row["actor_loss"], row["value_loss"], row["entropy"] = (x.mean() for x in losses)
            if curriculum:
                row["curriculum"] = trace
            return (params, opt_state, env_state, obs, log, step, key, schedule), row

        carry = (
            params,
            opt_state,
            env_state,
            timestep.obs,
            log,
            jnp.zeros((), jnp.int32),
            key,
            schedule,
        )
        (params, _, _, _, log, *_), metrics = jax.lax.scan(update, carry, jnp.arange(num_updates))
        return TrainResult(params, {**metrics, "episodes": log.episodes()})

    return train


def train_gymnasium(
    config: PPOConfig, env_id: str, train_contexts: Any, key, **options: Any
) -> TrainResult:
    """PPO on the host collector (:func:`contextrl.agents.host.train_on_host`, which takes the
    keyword ``options``: ``seed``, ``vectorization``, ``init_params``, environment options): for host
    environments (dm_control…) or any registered id.

    ``num_envs`` copies take contexts from ``train_contexts`` by ``config.context_selector``; acting
    and every update are compiled, the environment steps on the host. Returns the same
    ``TrainResult`` as :func:`make_train`; slower than the JAX path.
    """
    schedule = HostSchedule(0, config.num_updates, 1, config.num_steps)
    return train_on_host(
        "PPO", config, env_id, train_contexts, key, _HostLearner, schedule, **options
    )


class _HostLearner(HostLearner):
    """PPO's part of the host loop: sampling with values, the rollout, the clipped update."""

    def __init__(self, config: PPOConfig, collector, key, init_params=None):
        nets = _networks(config, *collector.agent_inputs)
        optimizer, value, learn = _learner(config, nets)

        @jax.jit
        def act(params, obs, context_vector, key):
            action, log_prob = _sample(nets, params, obs, context_vector, key)
            return action, _env_action(nets, action), log_prob, value(params, obs, context_vector)

        self._act, self._value, self._learn = act, jax.jit(value), jax.jit(learn)
        self._time_limit_reward = jax.jit(
            lambda params, step, context: _time_limit_reward(
                value, params, step, context, config.gamma
            )
        )
        self._key, init_key = jax.random.split(key)
        fresh = init_params is None
        self.params = _init_params(nets, config, init_key) if fresh else init_params
        self._opt_state = optimizer.init(self.params)
        self._rollout: list = []

    def act(self, obs, context, warmup):
        self._key, action_key = jax.random.split(self._key)
        self._action, env_action, self._log_prob, self._state_value = self._act(
            self.params, obs, context, action_key
        )
        return np.asarray(env_action)

    def store(self, obs, context, step, warmup):
        reward = step.reward
        if (step.truncated & ~step.terminated).any():  # else there is nothing to bootstrap
            reward = np.asarray(self._time_limit_reward(self.params, step, context))
        self._rollout.append(
            (obs, context, self._action, self._log_prob, self._state_value, reward, step.done)
        )
        self._next = step.obs, step.context

    def update(self):
        stacked = tuple(np.stack(column) for column in zip(*self._rollout, strict=True))
        self._rollout = []
        last_value = self._value(self.params, *self._next)
        self.params, self._opt_state, self._key, self._losses, _ = self._learn(
            self.params, self._opt_state, stacked, last_value, self._key
        )

    def row_metrics(self):
        return {
            "actor_loss": float(self._losses[0].mean()),
            "value_loss": float(self._losses[1].mean()),
            "entropy": float(self._losses[2].mean()),
        }


def make_policy(config: PPOConfig, env, train_contexts: Any, deterministic: bool = True) -> Policy:
    """The :class:`~contextrl.agents.common.Policy` of an agent trained on ``train_contexts`` in ``env``
    (a JAX or a host environment): the most likely action (discrete) or the Gaussian mean when
    deterministic, a sample otherwise; the action is what the environment takes (continuous actions
    clipped to the bounds)."""
    nets = _networks(config, *agent_inputs(config, env, train_contexts, "PPO"))

    def act(params, obs, context_vector, key):
        if deterministic:
            head, _ = _policy_outputs(nets, params, obs, context_vector)
            action = jnp.argmax(head, axis=-1) if nets.discrete else head
        else:
            action, _ = _sample(nets, params, obs, context_vector, key)
        return _env_action(nets, action)

    return Policy(act, nets.context, env.context_space)


def action_distribution(config: PPOConfig, env, train_contexts: Any) -> Callable:
    """``(params, obs, ctx) -> probabilities`` (discrete) or ``(mean, std)`` (continuous)."""
    nets = _networks(config, *agent_inputs(config, env, train_contexts, "PPO"))
    space = env.context_space

    def distribution(params, obs, ctx):
        head, log_std = _policy_outputs(nets, params, obs, nets.context.vector(space, ctx))
        return jax.nn.softmax(head) if nets.discrete else (head, jnp.exp(log_std))

    return distribution
