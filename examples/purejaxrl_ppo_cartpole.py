"""PPO written the PureJaxRL way, trained through the gymnax face on contextual CartPole.

The whole run (environment steps, GAE, minibatch updates) is one compiled function. Only the import
and the params differ from a gymnax script: every parallel copy gets its own pole length, because the
params of ``contextrl.gymnax`` are contexts and a sampled batch of contexts is a batch of params.

    python examples/purejaxrl_ppo_cartpole.py
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import optax

import contextrl as crl
import contextrl.gymnax as gymnax
from contextrl.core.spaces import Box


# ---- gymnax-style wrappers, as PureJaxRL users have them -------------------------------------------------
class GymnaxWrapper:
    """Forward every attribute the wrapper does not define to the wrapped environment."""

    def __init__(self, env):
        self._env = env

    def __getattr__(self, name):
        return getattr(self._env, name)


class FlattenObservationWrapper(GymnaxWrapper):
    """Observations as flat vectors."""

    def observation_space(self, params):
        space = self._env.observation_space(params)
        return Box(space.low.ravel(), space.high.ravel())

    def reset(self, key, params=None):
        obs, state = self._env.reset(key, params)
        return jnp.reshape(obs, (-1,)), state

    def step(self, key, state, action, params=None):
        obs, state, reward, done, info = self._env.step(key, state, action, params)
        return jnp.reshape(obs, (-1,)), state, reward, done, info


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class LogEnvState:
    env_state: Any
    episode_returns: jax.Array
    episode_lengths: jax.Array
    returned_episode_returns: jax.Array
    returned_episode_lengths: jax.Array


class LogWrapper(GymnaxWrapper):
    """Running return and length of the current episode; the last finished episode's in ``info``."""

    def reset(self, key, params=None):
        obs, env_state = self._env.reset(key, params)
        zero = jnp.zeros((), jnp.float32)
        return obs, LogEnvState(env_state, zero, zero, zero, zero)

    def step(self, key, state, action, params=None):
        obs, env_state, reward, done, info = self._env.step(key, state.env_state, action, params)
        episode_return = state.episode_returns + reward
        episode_length = state.episode_lengths + 1
        state = LogEnvState(
            env_state,
            episode_return * (1 - done),
            episode_length * (1 - done),
            jnp.where(done, episode_return, state.returned_episode_returns),
            jnp.where(done, episode_length, state.returned_episode_lengths),
        )
        info = {
            **info,
            "returned_episode_returns": state.returned_episode_returns,
            "returned_episode_lengths": state.returned_episode_lengths,
            "returned_episode": done,
        }
        return obs, state, reward, done, info


# ---- actor-critic ------------------------------------------------------------------------------------------
def dense_init(key, n_in, n_out, scale):
    return {"w": jax.nn.initializers.orthogonal(scale)(key, (n_in, n_out)), "b": jnp.zeros(n_out)}


def init_actor_critic(key, obs_size, num_actions, hidden=64):
    keys = jax.random.split(key, 6)
    sqrt2 = jnp.sqrt(2.0)
    return {
        "actor": [
            dense_init(keys[0], obs_size, hidden, sqrt2),
            dense_init(keys[1], hidden, hidden, sqrt2),
            dense_init(keys[2], hidden, num_actions, 0.01),
        ],
        "critic": [
            dense_init(keys[3], obs_size, hidden, sqrt2),
            dense_init(keys[4], hidden, hidden, sqrt2),
            dense_init(keys[5], hidden, 1, 1.0),
        ],
    }


def mlp(layers, x):
    for layer in layers[:-1]:
        x = jnp.tanh(x @ layer["w"] + layer["b"])
    return x @ layers[-1]["w"] + layers[-1]["b"]


def apply_actor_critic(params, obs):
    """(action logits, value)."""
    return mlp(params["actor"], obs), mlp(params["critic"], obs)[..., 0]


class Transition(NamedTuple):
    done: jax.Array
    action: jax.Array
    value: jax.Array
    reward: jax.Array
    log_prob: jax.Array
    obs: jax.Array
    info: dict


# ---- training ----------------------------------------------------------------------------------------------
CONFIG = {
    "LR": 2.5e-3,
    "NUM_ENVS": 16,
    "NUM_STEPS": 64,
    "TOTAL_TIMESTEPS": 100_000,
    "UPDATE_EPOCHS": 4,
    "NUM_MINIBATCHES": 4,
    "GAMMA": 0.99,
    "GAE_LAMBDA": 0.95,
    "CLIP_EPS": 0.2,
    "ENT_COEF": 0.01,
    "VF_COEF": 0.5,
    "MAX_GRAD_NORM": 0.5,
    "ANNEAL_LR": True,
    "POLE_LENGTHS": (0.25, 0.75),
}


def make_train(config):
    config = {**config}
    config["NUM_UPDATES"] = config["TOTAL_TIMESTEPS"] // config["NUM_STEPS"] // config["NUM_ENVS"]
    config["MINIBATCH_SIZE"] = config["NUM_ENVS"] * config["NUM_STEPS"] // config["NUM_MINIBATCHES"]
    env, default_params = gymnax.make("CartPole-v1")
    env = LogWrapper(FlattenObservationWrapper(env))

    def linear_schedule(count):
        fraction = (
            1.0
            - (count // (config["NUM_MINIBATCHES"] * config["UPDATE_EPOCHS"]))
            / config["NUM_UPDATES"]
        )
        return config["LR"] * fraction

    def train(rng):
        # One pole length per parallel copy: a batch of contexts is a batch of params.
        rng, context_rng = jax.random.split(rng)
        low, high = config["POLE_LENGTHS"]
        env_params = crl.sample(
            default_params, {"length": crl.Uniform(low, high)}, config["NUM_ENVS"], context_rng
        )

        rng, init_rng = jax.random.split(rng)
        obs_size = env.observation_space(default_params).shape[0]
        network_params = init_actor_critic(init_rng, obs_size, env.action_space(default_params).n)
        learning_rate = linear_schedule if config["ANNEAL_LR"] else config["LR"]
        tx = optax.chain(
            optax.clip_by_global_norm(config["MAX_GRAD_NORM"]),
            optax.adam(learning_rate, eps=1e-5),
        )
        opt_state = tx.init(network_params)

        rng, reset_rng = jax.random.split(rng)
        obsv, env_state = jax.vmap(env.reset)(
            jax.random.split(reset_rng, config["NUM_ENVS"]), env_params
        )

        def _update_step(runner_state, unused):
            def _env_step(runner_state, unused):
                network_params, opt_state, env_state, last_obs, rng = runner_state
                rng, action_rng, step_rng = jax.random.split(rng, 3)
                logits, value = apply_actor_critic(network_params, last_obs)
                action = jax.random.categorical(action_rng, logits)
                log_prob = jnp.take_along_axis(jax.nn.log_softmax(logits), action[:, None], 1)[:, 0]
                step_keys = jax.random.split(step_rng, config["NUM_ENVS"])
                obsv, env_state, reward, done, info = jax.vmap(env.step)(
                    step_keys, env_state, action, env_params
                )
                transition = Transition(done, action, value, reward, log_prob, last_obs, info)
                return (network_params, opt_state, env_state, obsv, rng), transition

            runner_state, traj_batch = jax.lax.scan(
                _env_step, runner_state, None, config["NUM_STEPS"]
            )
            network_params, opt_state, env_state, last_obs, rng = runner_state
            _, last_value = apply_actor_critic(network_params, last_obs)

            def _calculate_gae(traj_batch, last_value):
                def _get_advantages(gae_and_next_value, transition):
                    gae, next_value = gae_and_next_value
                    not_done = 1.0 - transition.done
                    delta = (
                        transition.reward
                        + config["GAMMA"] * next_value * not_done
                        - transition.value
                    )
                    gae = delta + config["GAMMA"] * config["GAE_LAMBDA"] * not_done * gae
                    return (gae, transition.value), gae

                _, advantages = jax.lax.scan(
                    _get_advantages,
                    (jnp.zeros_like(last_value), last_value),
                    traj_batch,
                    reverse=True,
                )
                return advantages, advantages + traj_batch.value

            advantages, targets = _calculate_gae(traj_batch, last_value)

            def _update_epoch(update_state, unused):
                def _update_minibatch(train_state, batch_info):
                    network_params, opt_state = train_state
                    traj_batch, advantages, targets = batch_info

                    def _loss_fn(params, traj_batch, gae, targets):
                        logits, value = apply_actor_critic(params, traj_batch.obs)
                        log_probs = jax.nn.log_softmax(logits)
                        log_prob = jnp.take_along_axis(log_probs, traj_batch.action[:, None], 1)[
                            :, 0
                        ]
                        value_clipped = traj_batch.value + (value - traj_batch.value).clip(
                            -config["CLIP_EPS"], config["CLIP_EPS"]
                        )
                        value_loss = (
                            0.5
                            * jnp.maximum(
                                jnp.square(value - targets), jnp.square(value_clipped - targets)
                            ).mean()
                        )
                        ratio = jnp.exp(log_prob - traj_batch.log_prob)
                        gae = (gae - gae.mean()) / (gae.std() + 1e-8)
                        actor_loss = -jnp.minimum(
                            ratio * gae,
                            jnp.clip(ratio, 1.0 - config["CLIP_EPS"], 1.0 + config["CLIP_EPS"])
                            * gae,
                        ).mean()
                        entropy = -(jnp.exp(log_probs) * log_probs).sum(-1).mean()
                        return (
                            actor_loss
                            + config["VF_COEF"] * value_loss
                            - config["ENT_COEF"] * entropy
                        )

                    grads = jax.grad(_loss_fn)(network_params, traj_batch, advantages, targets)
                    updates, opt_state = tx.update(grads, opt_state)
                    return (optax.apply_updates(network_params, updates), opt_state), None

                network_params, opt_state, traj_batch, advantages, targets, rng = update_state
                rng, permutation_rng = jax.random.split(rng)
                batch_size = config["MINIBATCH_SIZE"] * config["NUM_MINIBATCHES"]
                permutation = jax.random.permutation(permutation_rng, batch_size)
                batch = jax.tree_util.tree_map(
                    lambda x: x.reshape((batch_size, *x.shape[2:])),
                    (traj_batch, advantages, targets),
                )
                shuffled = jax.tree_util.tree_map(lambda x: jnp.take(x, permutation, axis=0), batch)
                minibatches = jax.tree_util.tree_map(
                    lambda x: jnp.reshape(x, (config["NUM_MINIBATCHES"], -1, *x.shape[1:])),
                    shuffled,
                )
                (network_params, opt_state), _ = jax.lax.scan(
                    _update_minibatch, (network_params, opt_state), minibatches
                )
                return (network_params, opt_state, traj_batch, advantages, targets, rng), None

            update_state = (network_params, opt_state, traj_batch, advantages, targets, rng)
            update_state, _ = jax.lax.scan(
                _update_epoch, update_state, None, config["UPDATE_EPOCHS"]
            )
            network_params, opt_state, _, _, _, rng = update_state
            runner_state = (network_params, opt_state, env_state, last_obs, rng)
            return runner_state, traj_batch.info

        rng, run_rng = jax.random.split(rng)
        runner_state = (network_params, opt_state, env_state, obsv, run_rng)
        runner_state, metrics = jax.lax.scan(
            _update_step, runner_state, None, config["NUM_UPDATES"]
        )
        return {"runner_state": runner_state, "metrics": metrics}

    return train


def returns_per_update(metrics) -> jax.Array:
    """Mean return of the episodes that finished in each update (NaN where none did)."""
    finished = metrics["returned_episode"]
    total = (metrics["returned_episode_returns"] * finished).sum(axis=(1, 2))
    return total / finished.sum(axis=(1, 2))


if __name__ == "__main__":
    start = time.perf_counter()
    out = jax.jit(make_train(CONFIG))(jax.random.key(42))
    returns = returns_per_update(out["metrics"])
    print(f"{time.perf_counter() - start:.1f} s; mean episode return per update:")
    print(" ".join(f"{r:.0f}" for r in returns[:: max(1, len(returns) // 20)]))
