"""Soft Actor-Critic for continuous actions (twin critics, tanh-squashed Gaussian policy, automatic
entropy tuning); the whole run one JAX function.

    config = sac.SACConfig(variant="concat_varying")
    config = sac.paper_config("Pendulum")               # the authors' SAC settings
    train = sac.make_train(config, env, train_contexts)
    result = jax.jit(jax.vmap(train))(keys)

``train(key, contexts=None, params=None)`` as in :mod:`contextrl.agents.ppo`. After a warm-up of
uniform random actions, each gradient step is ``policy_frequency`` rounds of (one vector step, one critic update)
followed by one actor (and temperature) update (none before ``policy_learning_starts`` steps); each
logging period is one metrics row.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from contextrl.agents import offpolicy
from contextrl.agents.authors import AuthorsSetting
from contextrl.agents.common import Policy, TrainResult, agent_inputs
from contextrl.agents.curricula import seen_contexts
from contextrl.agents.host import HostLearner, train_on_host
from contextrl.agents.networks import ConditionedMLP, ContextInput
from contextrl.agents.replay import Replay, transition, transition_example
from contextrl.agents.validation import ConfigError, check_positive, flat_observation_size

LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0


@dataclasses.dataclass(frozen=True)
class SACConfig(offpolicy.OffPolicyConfig):
    """SAC hyper-parameters (defaults: CleanRL's continuous-control settings)."""

    total_timesteps: int = 50_000
    num_envs: int = 1
    hidden_sizes: tuple[int, ...] = (256, 256)
    activation: str = "relu"
    buffer_size: int = 100_000
    """Replay capacity in transitions (over all copies)."""
    batch_size: int = 256
    """Transitions per gradient step."""
    n_step: int = 1
    """Steps summed in each return before bootstrapping."""
    tau: float = 0.005
    """Target-critic soft update rate (every critic update)."""
    policy_lr: float = 3e-4
    """Adam step size of the actor (and of the temperature)."""
    q_lr: float = 1e-3
    """Adam step size of the critics."""
    learning_starts: int = 5000
    """Random-action transitions collected before learning (paper: warmup_num_frames)."""
    policy_frequency: int = 2
    """Critic updates (one vector step each) per actor update (paper: pi_update_freq)."""
    policy_learning_starts: int = 0
    """Environment steps before the first actor update; until then only the critics learn (paper:
    pi_warmup_num_frames). Below ``learning_starts`` it changes nothing."""
    layer_norm: bool = False
    """The first hidden layer of actor and critics normalised (LayerNorm), then tanh: the networks
    of CARL's experiments."""
    alpha: float = 0.2
    """Entropy temperature (the initial one when autotune is on)."""
    autotune: bool = True
    """Tune the temperature towards an entropy of −(action dimensions)."""
    log_every: int = 1000
    """Environment steps per metrics row (rounded to whole actor updates)."""

    def validate(self) -> None:
        """Raise ConfigError for any value that cannot train."""
        super().validate()
        check_positive("policy_frequency", self.policy_frequency, integer=True)
        check_positive(
            "policy_learning_starts", self.policy_learning_starts, integer=True, allow_zero=True
        )
        for name in ("policy_lr", "q_lr", "alpha"):
            check_positive(name, getattr(self, name))
        self.check_schedule()

    @property
    def steps_per_update(self) -> int:
        return self.policy_frequency


# The authors' SAC settings. base.yaml (with algorithm/sac.yaml): n-step 5, gamma 0.9, a fixed
# entropy weight 0.2, batch 128, learning rate 1e-3 for actor and critics, critic targets with tau
# 0.001, 5,000 warm-up frames, the actor from frame 7,500 and every 4th step, replay 100,000, width
# 256 (two hidden layers, the first LayerNorm and tanh: experiments/context_gating/networks/sac.py).
# dm_control (environments/dmc/base.yaml, which each domain's file includes) and BipedalWalker
# override some of these. The appendix table gives DmcWalker and DmcQuadruped base.yaml's values,
# not dmc/base.yaml's: the files are what trained the figures.
_SAC_BASE = dict(
    n_step=5,
    gamma=0.9,
    alpha=0.2,
    autotune=False,
    batch_size=128,
    policy_lr=1e-3,
    q_lr=1e-3,
    tau=0.001,
    learning_starts=5000,
    policy_learning_starts=7500,
    policy_frequency=4,
    buffer_size=100_000,
    hidden_sizes=(256, 256),
    layer_norm=True,
)
_SAC_DMC = dict(
    _SAC_BASE,
    gamma=0.99,
    tau=0.005,
    policy_frequency=2,
    policy_lr=1e-4,
    q_lr=1e-4,
    batch_size=256,
    alpha=0.1,
    hidden_sizes=(1024, 1024),
    buffer_size=1_000_000,
)
_SAC_FILES = ("base.yaml", "algorithm/sac.yaml")
PAPER_SAC = {
    "Pendulum": AuthorsSetting(
        (*_SAC_FILES, "environments/classic_control/pendulum.yaml"), 100_000, _SAC_BASE
    ),
    **{
        f"Dmc{domain.title()}": AuthorsSetting(
            (*_SAC_FILES, "environments/dmc/base.yaml", f"environments/dmc/{domain}.yaml"),
            1_000_000,
            _SAC_DMC,
        )
        for domain in ("walker", "quadruped", "fish")
    },
    "BipedalWalker": AuthorsSetting(
        (*_SAC_FILES, "environments/box2d/bipedalwalker.yaml"),
        500_000,
        dict(
            _SAC_BASE,
            gamma=0.98,
            tau=0.02,
            policy_frequency=64,
            policy_lr=7.3e-4,
            q_lr=7.3e-4,
            batch_size=256,
        ),
    ),
}


def paper_config(env_name: str, **overrides: Any) -> SACConfig:
    """The authors' SAC settings (:data:`PAPER_SAC`) for Pendulum, BipedalWalker and the dm_control
    domains. What coax's SAC does differently: each step updates one critic, chosen by a coin flip
    (here both); its entropy term is coax's n-step entropy regulariser with weight ``alpha`` in
    the critics' targets and the policy objective (here SAC's −α log π of a sampled action); and
    its ``pi_targ_tau`` sets nothing, as its SAC keeps no actor target."""
    if env_name not in PAPER_SAC:
        raise ConfigError(f"no paper SAC setting for {env_name!r}; known: {sorted(PAPER_SAC)}")
    return SACConfig(**{**PAPER_SAC[env_name].options, **overrides})


@dataclasses.dataclass(frozen=True)
class _Networks:
    actor: ConditionedMLP
    critic: ConditionedMLP
    context: ContextInput
    action_low: np.ndarray
    action_high: np.ndarray

    @property
    def action_size(self) -> int:
        return self.action_low.shape[0]

    def to_env(self, squashed):
        """Map a squashed action in [−1, 1] to the environment's bounds."""
        return self.action_low + (squashed + 1.0) * 0.5 * (self.action_high - self.action_low)


def _networks(
    config: SACConfig, observation_space, action_space, context: ContextInput
) -> _Networks:
    """Actor and critics for these spaces (contextrl's or gymnasium's Box) and context input."""
    low, high = getattr(action_space, "low", None), getattr(action_space, "high", None)
    if low is None or len(action_space.shape) != 1 or hasattr(action_space, "n"):
        raise ConfigError(f"SAC needs a 1-D Box action space, got {action_space!r}")
    if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        raise ConfigError(
            f"SAC squashes actions into bounds; the action bounds are infinite: {action_space!r}"
        )
    obs_size = flat_observation_size("SAC", observation_space)
    common = dict(
        hidden_sizes=config.hidden_sizes,
        context=context,
        activation=config.activation,
        layer_norm=config.layer_norm,
    )
    action_size = action_space.shape[0]
    actor = ConditionedMLP(obs_size, 2 * action_size, out_scale=0.01, **common)
    critic = ConditionedMLP(obs_size + action_size, 1, out_scale=1.0, **common)
    return _Networks(actor, critic, context, np.asarray(low), np.asarray(high))


def _actor_head(nets: _Networks, params, obs, context_vector):
    out = nets.actor.apply(params, obs, context_vector)
    mean, log_std = jnp.split(out, 2, axis=-1)
    log_std = LOG_STD_MIN + 0.5 * (LOG_STD_MAX - LOG_STD_MIN) * (jnp.tanh(log_std) + 1.0)
    return mean, log_std


def _sample_action(nets: _Networks, params, obs, context_vector, key):
    """A squashed action in [−1, 1] and its log-probability (tanh change of variables)."""
    mean, log_std = _actor_head(nets, params, obs, context_vector)
    std = jnp.exp(log_std)
    noise = jax.random.normal(key, mean.shape)
    pre_tanh = mean + std * noise
    action = jnp.tanh(pre_tanh)
    log_prob = jnp.sum(
        -0.5 * noise**2 - log_std - 0.5 * jnp.log(2 * jnp.pi) - jnp.log(1 - action**2 + 1e-6),
        axis=-1,
    )
    return action, log_prob


def _twin_q(nets: _Networks, critic_params, obs, context_vector, action):
    """Both critics' values, shape (2, batch)."""
    inputs = jnp.concatenate([obs, action], axis=-1)
    return jax.vmap(lambda p: nets.critic.apply(p, inputs, context_vector).squeeze(-1))(
        critic_params
    )


def init_params(config: SACConfig, env, train_contexts: Any, key) -> dict:
    """Freshly initialised actor, twin critics and log-temperature."""
    return _init(_networks(config, *agent_inputs(config, env, train_contexts, "SAC")), config, key)


def _init(nets: _Networks, config: SACConfig, key) -> dict:
    actor_key, critic_key = jax.random.split(key)
    critics = [nets.critic.init(k) for k in jax.random.split(critic_key, 2)]
    return {
        "actor": nets.actor.init(actor_key),
        "critic": jax.tree_util.tree_map(lambda *x: jnp.stack(x), *critics),
        "log_alpha": jnp.asarray(math.log(config.alpha), jnp.float32),
    }


def _learner(config: SACConfig, nets: _Networks):
    """``init(key) -> (params, target_critic, opt_states)``, ``critic_update(params, target_critic,
    opt_states, batch, key)`` and ``actor_update(params, opt_states, batch, key)``: the algorithm,
    shared by the compiled loop and the host loop."""
    actor_optimizer = optax.adam(config.policy_lr)
    critic_optimizer = optax.adam(config.q_lr)
    alpha_optimizer = optax.adam(config.policy_lr)
    target_entropy = -float(nets.action_size)

    def init(key, params=None):
        params = _init(nets, config, key) if params is None else params
        opt_states = (
            actor_optimizer.init(params["actor"]),
            critic_optimizer.init(params["critic"]),
            alpha_optimizer.init(params["log_alpha"]),
        )
        return params, params["critic"], opt_states

    def critic_loss(critic_params, target_critic, actor_params, log_alpha, batch, key):
        next_action, next_log_prob = _sample_action(
            nets, actor_params, batch["next_obs"], batch["next_context"], key
        )
        next_q = _twin_q(
            nets, target_critic, batch["next_obs"], batch["next_context"], next_action
        ).min(axis=0)
        soft_value = next_q - jnp.exp(log_alpha) * next_log_prob
        target = jax.lax.stop_gradient(batch["reward"] + batch["discount"] * soft_value)
        q = _twin_q(nets, critic_params, batch["obs"], batch["context"], batch["action"])
        return 0.5 * jnp.mean(jnp.sum((q - target[None]) ** 2, axis=0))

    def actor_loss(actor_params, critic_params, log_alpha, batch, key):
        action, log_prob = _sample_action(nets, actor_params, batch["obs"], batch["context"], key)
        q = _twin_q(nets, critic_params, batch["obs"], batch["context"], action).min(axis=0)
        return jnp.mean(jnp.exp(log_alpha) * log_prob - q), log_prob

    def critic_update(params, target_critic, opt_states, batch, key):
        loss, grads = jax.value_and_grad(critic_loss)(
            params["critic"], target_critic, params["actor"], params["log_alpha"], batch, key
        )
        updates, critic_state = critic_optimizer.update(grads, opt_states[1], params["critic"])
        params = {**params, "critic": optax.apply_updates(params["critic"], updates)}
        target_critic = optax.incremental_update(params["critic"], target_critic, config.tau)
        return params, target_critic, (opt_states[0], critic_state, opt_states[2]), loss

    def actor_update(params, opt_states, batch, key):
        (loss, log_prob), grads = jax.value_and_grad(actor_loss, has_aux=True)(
            params["actor"], params["critic"], params["log_alpha"], batch, key
        )
        updates, actor_state = actor_optimizer.update(grads, opt_states[0], params["actor"])
        params = {**params, "actor": optax.apply_updates(params["actor"], updates)}
        alpha_state = opt_states[2]
        if config.autotune:
            entropy_gap = jax.lax.stop_gradient(log_prob + target_entropy).mean()
            alpha_grad = -entropy_gap  # d/d(log α) of −log α · (log π + H_target)
            updates, alpha_state = alpha_optimizer.update(
                alpha_grad, alpha_state, params["log_alpha"]
            )
            params = {**params, "log_alpha": params["log_alpha"] + updates}
        return params, (actor_state, opt_states[1], alpha_state), loss, jnp.exp(params["log_alpha"])

    return init, critic_update, actor_update


def make_train(config: SACConfig, env, train_contexts: Any) -> Callable[..., TrainResult]:
    """Validate everything now and return ``train(key, contexts=None) -> TrainResult`` (pure, jittable);
    ``train_contexts`` may be SPaCE or ADR (:mod:`contextrl.context.curricula`)."""
    nets = _networks(
        config, *agent_inputs(config, env, seen_contexts(train_contexts), "SAC", host=False)
    )
    init, critic_update, actor_update = _learner(config, nets)

    def value(params, obs, context_vector):
        """The twin critics' lesser value of the actor's mean action."""
        mean, _ = _actor_head(nets, params["actor"], obs, context_vector)
        return _twin_q(nets, params["critic"], obs, context_vector, jnp.tanh(mean)).min(axis=0)

    def update(learner, world, step, update_index):
        """``policy_frequency`` rounds of (one vector step, one critic update), then one actor update."""

        def critic_round(carry, _):
            (params, target_critic, opt_states), world = carry

            def explore(obs, context_vector, key):
                return _sample_action(nets, params["actor"], obs, context_vector, key)[0]

            world = step(world, explore)
            key, sample_key, target_key = jax.random.split(world.key, 3)
            batch = world.replay.sample(sample_key, config.batch_size, config.n_step, config.gamma)
            *learner, loss = critic_update(params, target_critic, opt_states, batch, target_key)
            return (tuple(learner), world._replace(key=key)), (loss, batch)

        (learner, world), (critic_losses, batches) = jax.lax.scan(
            critic_round, (learner, world), None, config.policy_frequency
        )
        params, target_critic, opt_states = learner
        batch = jax.tree_util.tree_map(lambda x: x[-1], batches)
        key, actor_key = jax.random.split(world.key)
        updated = actor_update(params, opt_states, batch, actor_key)
        if config.policy_learning_starts > config.warmup_steps * config.num_envs:
            ready = world.step >= config.policy_learning_starts
            params, opt_states = jax.tree_util.tree_map(
                lambda new, old: jnp.where(ready, new, old), updated[:2], (params, opt_states)
            )
            loss, alpha = jnp.where(ready, updated[2], jnp.nan), jnp.exp(params["log_alpha"])
        else:
            params, opt_states, loss, alpha = updated
        metrics = (critic_losses.mean(), loss, alpha)
        return (params, target_critic, opt_states), world._replace(key=key), metrics

    def row_metrics(metrics):
        critic_losses, actor_losses, alphas = metrics
        return {
            "critic_loss": critic_losses.mean(),
            "actor_loss": jnp.nanmean(actor_losses),  # NaN before the first actor update
            "alpha": alphas[-1],
        }

    shape = (config.num_envs, nets.action_size)
    algorithm = offpolicy.Algorithm(
        name="SAC",
        context=nets.context,
        action_example=jnp.zeros(shape, jnp.float32),
        random_action=lambda key: jax.random.uniform(key, shape, minval=-1, maxval=1),
        to_env=nets.to_env,
        init=init,
        update=update,
        row_metrics=row_metrics,
        value=value,
    )
    return offpolicy.make_train(config, env, train_contexts, algorithm)


def train_gymnasium(
    config: SACConfig, env_id: str, train_contexts: Any, key, **options: Any
) -> TrainResult:
    """SAC on the host collector (:func:`contextrl.agents.host.train_on_host`, which takes the
    keyword ``options``: ``seed``, ``vectorization``, ``init_params``, environment options): for host
    environments (dm_control…) or any registered id, with the same schedule as :func:`make_train`
    (warm-up, then ``policy_frequency`` rounds of one vector step and one critic update per actor
    update). Returns the same ``TrainResult``."""
    return train_on_host(
        "SAC", config, env_id, train_contexts, key, _HostLearner, config.schedule, **options
    )


class _HostLearner(HostLearner):
    """SAC's part of the host loop: after the warm-up, two compiled calls per vector step.

    Parameters, optimiser states, replay buffer and key stay on the device and are donated to the
    calls: one stores the step in place, the other samples a batch, updates the critics (and, on a
    round's last step, the actor and temperature) and draws the next exploring action from the
    updated actor, the order of :func:`make_train`, so ``update`` has nothing left to do.
    """

    def __init__(self, config: SACConfig, collector, key, init_params=None):
        nets = _networks(config, *collector.agent_inputs)
        init, critic_update, actor_update = _learner(config, nets)
        num_envs = config.num_envs
        self._nets, self._num_envs = nets, num_envs
        self._policy_frequency, self._round = config.policy_frequency, 0
        self._policy_starts, self._steps = config.policy_learning_starts, 0
        action = np.zeros((num_envs, nets.action_size), np.float32)
        example = transition_example(collector.obs, collector.context, action)

        @jax.jit
        def start(key, example, init_params):
            key, init_key = jax.random.split(key)
            params, target_critic, opt_states = init(init_key, init_params)
            state = {
                "params": params,
                "target_critic": target_critic,
                "opt_states": opt_states,
                "key": key,
            }
            return state, Replay.create(config.replay_capacity, example)

        @functools.partial(jax.jit, donate_argnums=0)
        def first_action(state, obs, context_vector):
            key, action_key = jax.random.split(state["key"])
            actor = state["params"]["actor"]
            action = _sample_action(nets, actor, obs, context_vector, action_key)[0]
            return {**state, "key": key}, action

        # Storing is its own call: sampling from the buffer a call has just written makes XLA copy
        # whole buffers, while a separate in-place write costs nothing.
        add = jax.jit(lambda replay, transition: replay.add(transition), donate_argnums=0)

        @functools.partial(jax.jit, donate_argnums=0, static_argnums=3)
        def learn_and_act(state, replay, next_inputs, with_actor):
            key, sample_key, critic_key, actor_key, action_key = jax.random.split(state["key"], 5)
            batch = replay.sample(sample_key, config.batch_size, config.n_step, config.gamma)
            params, target_critic, opt_states, critic_loss = critic_update(
                state["params"], state["target_critic"], state["opt_states"], batch, critic_key
            )
            losses = {"critic_loss": critic_loss}
            if with_actor:
                params, opt_states, actor_loss, alpha = actor_update(
                    params, opt_states, batch, actor_key
                )
                losses.update(actor_loss=actor_loss, alpha=alpha)
            obs, context_vector = next_inputs
            action = _sample_action(nets, params["actor"], obs, context_vector, action_key)[0]
            state = {
                "params": params,
                "target_critic": target_critic,
                "opt_states": opt_states,
                "key": key,
            }
            return state, action, losses

        self._state, self._replay = start(key, example, init_params)
        self._first_action, self._add, self._learn_and_act = first_action, add, learn_and_act
        self._rng = np.random.default_rng(np.asarray(jax.random.key_data(key)).ravel())
        self._next_action = None
        self._losses: list[dict] = []

    @property
    def params(self):
        return self._state["params"]

    def act(self, obs, context, warmup):
        if warmup:
            shape = (self._num_envs, self._nets.action_size)
            self._action = self._rng.uniform(-1.0, 1.0, shape).astype(np.float32)
        elif self._next_action is None:  # the first step after the warm-up
            self._state, action = self._first_action(self._state, obs, context)
            self._action = np.asarray(action)
        else:
            self._action = np.asarray(self._next_action)
        return self._nets.to_env(self._action)

    def store(self, obs, context, step, warmup):
        self._replay = self._add(self._replay, transition(obs, context, self._action, step))
        self._steps += self._num_envs
        if warmup:
            return
        self._round = (self._round + 1) % self._policy_frequency
        with_actor = self._round == 0 and self._steps >= self._policy_starts
        self._state, self._next_action, losses = self._learn_and_act(
            self._state, self._replay, (step.obs, step.context), with_actor
        )
        self._losses.append(losses)

    def update(self):
        """Done inside the round's last ``store``."""

    def row_metrics(self):
        losses, self._losses = jax.device_get(self._losses), []
        actor_losses = [x["actor_loss"] for x in losses if "actor_loss" in x]
        return {
            "critic_loss": float(np.mean([x["critic_loss"] for x in losses])),
            "actor_loss": float(np.mean(actor_losses)) if actor_losses else float("nan"),
            "alpha": float(np.exp(self._state["params"]["log_alpha"])),
        }


def make_policy(config: SACConfig, env, train_contexts: Any, deterministic: bool = True) -> Policy:
    """The :class:`~contextrl.agents.common.Policy` of an agent trained on ``train_contexts`` in ``env``
    (a JAX or a host environment): actions in the environment's bounds, the tanh of the mean when
    deterministic, a sample otherwise."""
    nets = _networks(config, *agent_inputs(config, env, train_contexts, "SAC"))

    def act(params, obs, context_vector, key):
        if deterministic:
            mean, _ = _actor_head(nets, params["actor"], obs, context_vector)
            return nets.to_env(jnp.tanh(mean))
        action, _ = _sample_action(nets, params["actor"], obs, context_vector, key)
        return nets.to_env(action)

    return Policy(act, nets.context, env.context_space)


def action_mean(config: SACConfig, env, train_contexts: Any) -> Callable:
    """``(params, obs, ctx) -> deterministic action`` (for inspecting the context's effect)."""
    policy = make_policy(config, env, train_contexts, deterministic=True)
    return lambda params, obs, ctx: policy(params, obs, ctx, None)
