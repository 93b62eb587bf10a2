"""A replay buffer in JAX arrays with n-step returns, shared by DQN/C51 and SAC.

Transitions are stored in time order per environment copy (shape ``(capacity, num_envs, ...)``), so an
n-step return is gathered at sampling time: rewards are summed until the episode ends, and the target
bootstraps from the last stored ``next_obs`` (the final observation when the episode was cut by the
time limit, no bootstrap when it terminated).
"""

from __future__ import annotations

import dataclasses
from typing import Any, TypedDict

import jax
import jax.numpy as jnp


class Transition(TypedDict):
    """One vector step as the replay stores it, every field with a leading ``num_envs`` axis; the
    compiled loops and the host loop build it alike, with :func:`transition`."""

    obs: Any
    context: Any  # the agent's context input
    action: Any
    reward: Any
    terminated: Any
    done: Any
    next_obs: Any  # the final observation where the episode ended


def transition(obs, context, action, step) -> Transition:
    """The transition of ``step`` (a JAX ``TimeStep`` or a host step) taken with ``action`` from
    ``obs`` and ``context``."""
    return Transition(
        obs=obs,
        context=context,
        action=action,
        reward=step.reward,
        terminated=step.terminated,
        done=step.done,
        next_obs=step.final_obs,
    )


def transition_example(obs, context, action) -> Transition:
    """A transition shaped like one vector step from ``obs``, to size a buffer."""
    num_envs = obs.shape[0]
    return Transition(
        obs=obs,
        context=context,
        action=action,
        reward=jnp.zeros((num_envs,), jnp.float32),
        terminated=jnp.zeros((num_envs,), bool),
        done=jnp.zeros((num_envs,), bool),
        next_obs=obs,
    )


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Replay:
    """Ring buffer of vector steps: ``data[name]`` has shape ``(capacity, num_envs, ...)``."""

    data: dict
    position: jax.Array
    size: jax.Array

    @classmethod
    def create(cls, capacity: int, example: Transition) -> Replay:
        """An empty buffer for ``capacity`` vector steps shaped like ``example`` (one vector step)."""
        data = {
            name: jnp.zeros((capacity,) + jnp.shape(value), jnp.asarray(value).dtype)
            for name, value in example.items()
        }
        zero = jnp.zeros((), jnp.int32)
        return cls(data, zero, zero)

    @property
    def capacity(self) -> int:
        return next(iter(self.data.values())).shape[0]

    def add(self, transition: Transition) -> Replay:
        """Store one vector step."""
        data = {
            name: buffer.at[self.position].set(transition[name])
            for name, buffer in self.data.items()
        }
        return Replay(
            data,
            (self.position + 1) % self.capacity,
            jnp.minimum(self.size + 1, self.capacity),
        )

    def sample(self, key, batch_size: int, n_step: int, gamma: float) -> dict:
        """A batch of n-step transitions: ``obs``, ``context``, ``action``, ``reward`` (the discounted
        n-step sum), ``discount`` (γ^steps, 0 after a termination), ``next_obs``, ``next_context``.

        Only start points whose n following steps are all stored are drawn (the newest n−1 wait).
        """
        time_key, env_key = jax.random.split(key)
        num_envs = self.data["reward"].shape[1]
        valid = jnp.maximum(self.size - (n_step - 1), 1)
        offset = jax.random.randint(time_key, (batch_size,), 0, valid)
        start = (self.position - self.size + offset) % self.capacity
        copy = jax.random.randint(env_key, (batch_size,), 0, num_envs)

        def at(name, k):
            return self.data[name][(start + k) % self.capacity, copy]

        total = jnp.zeros((batch_size,), jnp.float32)
        alive = jnp.ones((batch_size,), bool)
        discount = jnp.zeros((batch_size,), jnp.float32)
        next_obs = at("next_obs", 0)
        for k in range(n_step):
            reward, terminated, done = at("reward", k), at("terminated", k), at("done", k)
            total = total + jnp.where(alive, gamma**k * reward, 0.0)
            discount = jnp.where(alive, jnp.where(terminated, 0.0, gamma ** (k + 1)), discount)
            next_obs = jnp.where(alive[:, None], at("next_obs", k), next_obs)
            alive = alive & ~done
        # Within one episode the context does not change, so the bootstrap uses the start's context.
        context = at("context", 0)
        return {
            "obs": at("obs", 0),
            "context": context,
            "action": at("action", 0),
            "reward": total,
            "discount": discount,
            "next_obs": next_obs,
            "next_context": context,
        }
