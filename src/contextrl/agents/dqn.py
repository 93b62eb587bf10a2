"""DQN with n-step returns, and C51 (distributional) as an option; the whole run one JAX function.

    config = dqn.DQNConfig(distributional=True)          # C51
    config = dqn.paper_config("CartPole")                # the authors' C51 settings
    train = dqn.make_train(config, env, train_contexts)
    result = jax.jit(jax.vmap(train))(keys)

``train(key, contexts=None)`` as in :mod:`contextrl.agents.ppo`. The run has three phases inside one
compiled function: a warm-up of random actions that fills the replay buffer, then rows of
(``train_frequency`` vector steps, one gradient step) repeated; each logging period is one metrics row.
"""

from __future__ import annotations

import dataclasses
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
from contextrl.agents.validation import (
    ConfigError,
    check_fraction,
    check_positive,
    flat_observation_size,
)

EXPLORATIONS = ("epsilon", "boltzmann")


@dataclasses.dataclass(frozen=True)
class DQNConfig(offpolicy.OffPolicyConfig):
    """DQN / C51 hyper-parameters (defaults: a fast CartPole setting; see :func:`paper_config`)."""

    hidden_sizes: tuple[int, ...] = (128, 128)
    activation: str = "relu"
    learning_rate: float = 1e-3
    """Adam step size."""
    buffer_size: int = 100_000
    """Replay capacity in transitions (over all copies)."""
    batch_size: int = 128
    """Transitions per gradient step."""
    n_step: int = 3
    """Steps summed in each return before bootstrapping."""
    learning_starts: int = 5000
    """Random-action transitions collected before the first gradient step (paper: warmup)."""
    train_frequency: int = 1
    """Vector steps between gradient steps."""
    tau: float = 1.0
    """Target-network update rate (1: hard copy)."""
    target_update_interval: int = 250
    """Gradient steps between target updates."""
    max_grad_norm: float = 10.0
    """Global gradient-norm clip."""
    double: bool = False
    """Double Q-learning: the next action chosen by the online network, valued by the target one."""
    exploration: str = "epsilon"
    """"epsilon" (ε-greedy, linearly decayed) or "boltzmann" (softmax of Q / temperature)."""
    start_epsilon: float = 1.0
    """ε at the start of training (after warm-up)."""
    end_epsilon: float = 0.05
    """ε after the decay."""
    exploration_fraction: float = 0.3
    """Fraction of the run over which ε decays."""
    temperature: float = 0.1
    """Boltzmann temperature (paper: pi_temperature)."""
    distributional: bool = False
    """C51: learn a categorical return distribution instead of its mean."""
    num_atoms: int = 51
    """C51 atoms."""
    v_min: float = -100.0
    """C51 support lower end (paper: q_min_value)."""
    v_max: float = 100.0
    """C51 support upper end (paper: q_max_value)."""
    log_every: int = 1000
    """Environment steps per metrics row (rounded to whole gradient steps)."""

    def validate(self) -> None:
        """Raise ConfigError for any value that cannot train."""
        super().validate()
        for name in ("train_frequency", "target_update_interval", "num_atoms"):
            check_positive(name, getattr(self, name), integer=True)
        for name in ("learning_rate", "max_grad_norm", "temperature"):
            check_positive(name, getattr(self, name))
        for name in ("start_epsilon", "end_epsilon", "exploration_fraction"):
            check_fraction(name, getattr(self, name))
        if self.exploration not in EXPLORATIONS:
            raise ConfigError(
                f"exploration: unknown {self.exploration!r}; choose one of {list(EXPLORATIONS)}"
            )
        for name in ("v_min", "v_max"):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not math.isfinite(value)
            ):
                raise ConfigError(f"{name} must be a finite number, got {value!r}")
        if self.distributional and (self.v_min >= self.v_max or self.num_atoms < 2):
            raise ConfigError(
                f"C51 needs v_min < v_max and at least 2 atoms, got v_min={self.v_min}, "
                f"v_max={self.v_max}, num_atoms={self.num_atoms}"
            )
        self.check_schedule()

    @property
    def steps_per_update(self) -> int:
        return self.train_frequency


# The authors' C51 settings: base.yaml (n-step 5, batch 128, learning rate 1e-3, soft target updates
# with tau 0.001 after every gradient step, 5,000 warm-up frames, replay 100,000, width 256),
# algorithm/c51.yaml (Boltzmann exploration with temperature 0.1, gamma 0.99, 51 atoms) and each
# environment's file (the return support; MountainCar's width 32). The Q-network of CARL's
# experiments/context_gating/networks/c51.py has three hidden layers of that width. The appendix
# table lists the same values (the depth and the budgets aside).
_C51_BASE = dict(
    distributional=True,
    num_envs=1,
    n_step=5,
    gamma=0.99,
    batch_size=128,
    learning_rate=1e-3,
    tau=0.001,
    target_update_interval=1,
    learning_starts=5000,
    buffer_size=100_000,
    exploration="boltzmann",
    temperature=0.1,
    num_atoms=51,
    hidden_sizes=(256, 256, 256),
    double=True,  # coax's DoubleQLearning
)
_C51_FILES = ("base.yaml", "algorithm/c51.yaml")
PAPER_C51 = {
    "CartPole": AuthorsSetting(
        (*_C51_FILES, "environments/classic_control/cartpole.yaml"),
        100_000,
        {**_C51_BASE, "v_min": 0.0, "v_max": 110.0},
    ),
    "Acrobot": AuthorsSetting(
        (*_C51_FILES, "environments/classic_control/acrobot.yaml"),
        150_000,
        {**_C51_BASE, "v_min": -50.0, "v_max": 0.0},
    ),
    "MountainCar": AuthorsSetting(
        (*_C51_FILES, "environments/classic_control/mountaincar.yaml"),
        300_000,
        {**_C51_BASE, "v_min": -100.0, "v_max": 100.0, "hidden_sizes": (32, 32, 32)},
    ),
    "LunarLander": AuthorsSetting(
        (*_C51_FILES, "environments/box2d/lunarlander.yaml"),
        200_000,
        {**_C51_BASE, "v_min": -100.0, "v_max": 100.0},
    ),
}


def paper_config(env_name: str, **overrides: Any) -> DQNConfig:
    """The authors' C51 settings (:data:`PAPER_C51`) for CartPole, Acrobot, MountainCar or
    LunarLander. What coax's C51 does differently: its Q-function takes the action as an input (one
    output distribution per state–action pair) where this one outputs every action's, and its
    gradients are not clipped (here: ``max_grad_norm`` 10)."""
    if env_name not in PAPER_C51:
        raise ConfigError(f"no paper C51 setting for {env_name!r}; known: {sorted(PAPER_C51)}")
    return DQNConfig(**{**PAPER_C51[env_name].options, **overrides})


@dataclasses.dataclass(frozen=True)
class _Networks:
    q: ConditionedMLP
    context: ContextInput
    num_actions: int
    atoms: jax.Array | None


def _networks(
    config: DQNConfig, observation_space, action_space, context: ContextInput
) -> _Networks:
    """The Q-network for these spaces (contextrl's or gymnasium's) and context input."""
    if not hasattr(action_space, "n"):
        raise ConfigError(f"DQN/C51 needs a Discrete action space, got {action_space!r}")
    obs_size = flat_observation_size("DQN", observation_space)
    num_actions = int(action_space.n)
    outputs = num_actions * (config.num_atoms if config.distributional else 1)
    q = ConditionedMLP(
        obs_size,
        outputs,
        config.hidden_sizes,
        context,
        config.activation,
        out_scale=1.0,
    )
    atoms = (
        jnp.linspace(config.v_min, config.v_max, config.num_atoms)
        if config.distributional
        else None
    )
    return _Networks(q, context, num_actions, atoms)


def _q_values(nets: _Networks, params, obs, context_vector):
    """Expected returns per action, and the per-action atom logits for C51 (else None)."""
    out = nets.q.apply(params, obs, context_vector)
    if nets.atoms is None:
        return out, None
    logits = out.reshape(out.shape[:-1] + (nets.num_actions, nets.atoms.shape[0]))
    return jnp.sum(jax.nn.softmax(logits) * nets.atoms, axis=-1), logits


def init_params(config: DQNConfig, env, train_contexts: Any, key) -> dict:
    """Freshly initialised Q-network parameters."""
    return _networks(config, *agent_inputs(config, env, train_contexts, "DQN")).q.init(key)


def _explore(config: DQNConfig, nets: _Networks, q, key, epsilon):
    """An exploring action from the Q-values: Boltzmann, or ε-greedy with probability ``epsilon``."""
    explore_key, random_key, boltzmann_key = jax.random.split(key, 3)
    if config.exploration == "boltzmann":
        return jax.random.categorical(boltzmann_key, q / config.temperature)
    random_action = jax.random.randint(random_key, q.shape[:-1], 0, nets.num_actions)
    explore = jax.random.uniform(explore_key, q.shape[:-1]) < epsilon
    return jnp.where(explore, random_action, jnp.argmax(q, axis=-1))


def td_loss(config: DQNConfig, nets: _Networks, params, target_params, batch) -> jax.Array:
    """The TD loss of a batch: squared error to the n-step target (DQN), or the cross-entropy to
    the projected target distribution (C51)."""
    q, logits = _q_values(nets, params, batch["obs"], batch["context"])
    action = batch["action"]
    next_q, next_logits = _q_values(nets, target_params, batch["next_obs"], batch["next_context"])
    chooser = (
        _q_values(nets, params, batch["next_obs"], batch["next_context"])[0]
        if config.double
        else next_q
    )
    next_action = jnp.argmax(chooser, axis=-1)
    if nets.atoms is None:
        next_value = jnp.take_along_axis(next_q, next_action[:, None], axis=-1).squeeze(-1)
        target = batch["reward"] + batch["discount"] * next_value
        chosen = jnp.take_along_axis(q, action[:, None], axis=-1).squeeze(-1)
        return jnp.mean((chosen - jax.lax.stop_gradient(target)) ** 2)
    next_probs = jax.nn.softmax(
        jnp.take_along_axis(next_logits, next_action[:, None, None], axis=1).squeeze(1)
    )
    # Project the shifted support r + γ^n z back onto the atoms (linear interpolation).
    shifted = batch["reward"][:, None] + batch["discount"][:, None] * nets.atoms[None, :]
    spacing = (config.v_max - config.v_min) / (config.num_atoms - 1)
    position = (jnp.clip(shifted, config.v_min, config.v_max) - config.v_min) / spacing
    weight = jnp.clip(1.0 - jnp.abs(position[:, :, None] - jnp.arange(config.num_atoms)), 0, 1)
    target = jax.lax.stop_gradient(jnp.einsum("bj,bji->bi", next_probs, weight))
    chosen = jnp.take_along_axis(logits, action[:, None, None], axis=1).squeeze(1)
    return -jnp.mean(jnp.sum(target * jax.nn.log_softmax(chosen), axis=-1))


def _learner(config: DQNConfig, nets: _Networks):
    """The optimiser, ``act(params, obs, context, key, epsilon)``, ``learn(params, target_params,
    opt_state, replay, key, update_index)`` (one gradient step, then the target update) and the
    exploration schedule: the algorithm, shared by the compiled loop and the host loop."""
    optimizer = optax.chain(
        optax.clip_by_global_norm(config.max_grad_norm), optax.adam(config.learning_rate)
    )
    decay_steps = max(1, int(config.exploration_fraction * config.num_updates))

    def act(params, obs, context_vector, key, epsilon):
        q, _ = _q_values(nets, params, obs, context_vector)
        return _explore(config, nets, q, key, epsilon)

    def learn(params, target_params, opt_state, replay, key, update_index):
        batch = replay.sample(key, config.batch_size, config.n_step, config.gamma)
        loss, grads = jax.value_and_grad(
            lambda online: td_loss(config, nets, online, target_params, batch)
        )(params)
        updates, opt_state = optimizer.update(grads, opt_state, params)
        params = optax.apply_updates(params, updates)
        refresh = (update_index + 1) % config.target_update_interval == 0
        target_params = jax.tree_util.tree_map(
            lambda online, target: jnp.where(
                refresh, config.tau * online + (1 - config.tau) * target, target
            ),
            params,
            target_params,
        )
        return params, target_params, opt_state, loss

    def epsilon_at(update_index):
        fraction = jnp.minimum(update_index / decay_steps, 1.0)
        return config.start_epsilon + fraction * (config.end_epsilon - config.start_epsilon)

    return optimizer, act, learn, epsilon_at


def make_train(config: DQNConfig, env, train_contexts: Any) -> Callable[..., TrainResult]:
    """Validate everything now and return ``train(key, contexts=None) -> TrainResult`` (pure, jittable);
    ``train_contexts`` may be SPaCE or ADR (:mod:`contextrl.context.curricula`)."""
    nets = _networks(
        config, *agent_inputs(config, env, seen_contexts(train_contexts), "DQN", host=False)
    )
    optimizer, act, learn, epsilon_at = _learner(config, nets)

    def init(key, params):
        if params is None:  # given params: continue training them (population-based tuning)
            params = nets.q.init(key)
        return params, params, optimizer.init(params)

    def update(learner, world, step, update_index):
        """``train_frequency`` vector steps of the exploring policy, then one gradient step."""
        params, target_params, opt_state = learner
        epsilon = epsilon_at(update_index)

        def policy_step(world, _):
            return step(world, lambda obs, ctx, key: act(params, obs, ctx, key, epsilon)), None

        world = jax.lax.scan(policy_step, world, None, config.train_frequency)[0]
        key, sample_key = jax.random.split(world.key)
        *learner, loss = learn(
            params, target_params, opt_state, world.replay, sample_key, update_index
        )
        return tuple(learner), world._replace(key=key), loss

    num_envs = config.num_envs
    algorithm = offpolicy.Algorithm(
        name="C51" if config.distributional else "DQN",
        context=nets.context,
        action_example=jnp.zeros((num_envs,), jnp.int32),
        random_action=lambda key: jax.random.randint(key, (num_envs,), 0, nets.num_actions),
        to_env=lambda action: action,
        init=init,
        update=update,
        row_metrics=lambda losses: {"loss": losses.mean()},
        value=lambda params, obs, ctx: _q_values(nets, params, obs, ctx)[0].max(axis=-1),
    )
    return offpolicy.make_train(config, env, train_contexts, algorithm)


def train_gymnasium(
    config: DQNConfig, env_id: str, train_contexts: Any, key, **options: Any
) -> TrainResult:
    """DQN/C51 on the host collector (:func:`contextrl.agents.host.train_on_host`, which takes the
    keyword ``options``: ``seed``, ``vectorization``, ``init_params``, environment options): for host
    environments (RNA design, Box2D…) or any registered id, with the schedule of :func:`make_train`
    (warm-up, then ``train_frequency`` vector steps per gradient step). Returns the same
    ``TrainResult``."""
    return train_on_host(
        "DQN", config, env_id, train_contexts, key, _HostLearner, config.schedule, **options
    )


class _HostLearner(HostLearner):
    """DQN/C51's part of the host loop: ε-greedy (or Boltzmann) acting, replay, gradient steps."""

    def __init__(self, config: DQNConfig, collector, key, init_params=None):
        nets = _networks(config, *collector.agent_inputs)
        optimizer, act, learn, self._epsilon_at = _learner(config, nets)
        self._num_actions, self._num_envs = nets.num_actions, config.num_envs
        key, init_key = jax.random.split(key)
        self.params = nets.q.init(init_key) if init_params is None else init_params
        self._target_params, self._opt_state = self.params, optimizer.init(self.params)
        action = np.zeros((self._num_envs,), np.int32)
        example = transition_example(collector.obs, collector.context, action)
        # Own buffers: every step donates them.
        self._replay = jax.tree_util.tree_map(
            jnp.copy, Replay.create(config.replay_capacity, example)
        )
        self._add = jax.jit(lambda replay, transition: replay.add(transition), donate_argnums=(0,))
        self._learn, self._explore = jax.jit(learn), jax.jit(act)
        self._rng = np.random.default_rng(np.asarray(jax.random.key_data(key)).ravel())
        self._key, self._update_index, self._losses = key, 0, []

    def act(self, obs, context, warmup):
        if warmup:
            self._action = self._rng.integers(0, self._num_actions, self._num_envs)
        else:
            self._key, action_key = jax.random.split(self._key)
            epsilon = self._epsilon_at(self._update_index)
            self._action = np.asarray(self._explore(self.params, obs, context, action_key, epsilon))
        return self._action

    def store(self, obs, context, step, warmup):
        action = self._action.astype(np.int32)
        self._replay = self._add(self._replay, transition(obs, context, action, step))

    def update(self):
        self._key, sample_key = jax.random.split(self._key)
        self.params, self._target_params, self._opt_state, loss = self._learn(
            self.params,
            self._target_params,
            self._opt_state,
            self._replay,
            sample_key,
            self._update_index,
        )
        self._losses.append(loss)
        self._update_index += 1

    def row_metrics(self):
        losses, self._losses = self._losses, []
        return {"loss": float(np.mean(losses))}


def make_policy(config: DQNConfig, env, train_contexts: Any, deterministic: bool = True) -> Policy:
    """The :class:`~contextrl.agents.common.Policy` of an agent trained on ``train_contexts`` in ``env``
    (a JAX or a host environment): greedy, or exploring (final ε or Boltzmann)."""
    nets = _networks(config, *agent_inputs(config, env, train_contexts, "DQN"))

    def act(params, obs, context_vector, key):
        q, _ = _q_values(nets, params, obs, context_vector)
        if deterministic:
            return jnp.argmax(q, axis=-1)
        return _explore(config, nets, q, key, config.end_epsilon)

    return Policy(act, nets.context, env.context_space)


def q_values(config: DQNConfig, env, train_contexts: Any) -> Callable:
    """``(params, obs, ctx) -> expected return per action``."""
    nets = _networks(config, *agent_inputs(config, env, train_contexts, "DQN"))
    space = env.context_space

    def values(params, obs, ctx):
        return _q_values(nets, params, obs, nets.context.vector(space, ctx))[0]

    return values
