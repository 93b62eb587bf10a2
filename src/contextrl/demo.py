"""A first look: one fixed CartPole controller rolled out under several pole lengths at once.

    python -m contextrl.demo

The controller pushes the cart towards the side the pole leans to. It balances the default pole, but
its return changes with the pole's length: the context matters, which is what contextual RL is about.
"""

import time

import jax
import jax.numpy as jnp
import numpy as np

import contextrl as crl

LENGTHS = (0.05, 0.1, 0.25, 0.5, 1.0, 2.0, 4.0)
EPISODES_PER_LENGTH = 256


def lean_controller(obs):
    """Push right when the pole leans or falls right (a hand-written policy, no learning)."""
    _, _, theta, theta_dot = obs
    return (theta + 0.3 * theta_dot > 0).astype(jnp.int32)


def episode_returns(env, contexts, key):
    """Return of one full episode per context, all copies stepped together in one compiled loop."""
    n = len(contexts)
    reset_key, run_key = jax.random.split(key)
    state, ts = jax.vmap(env.reset)(jax.random.split(reset_key, n), contexts)

    def body(carry, step_key):
        state, obs, total, running = carry
        action = jax.vmap(lean_controller)(obs)
        state, ts = jax.vmap(env.step)(jax.random.split(step_key, n), state, action, contexts)
        total = total + ts.reward * running
        return (state, ts.obs, total, running & ~ts.done), None

    carry = (state, ts.obs, jnp.zeros(n), jnp.ones(n, bool))
    (_, _, total, _), _ = jax.lax.scan(body, carry, jax.random.split(run_key, env.max_steps))
    return total


def main() -> None:
    env = crl.make("CartPole")
    lengths = np.repeat(np.array(LENGTHS, np.float32), EPISODES_PER_LENGTH)
    contexts = env.context(length=lengths)
    start = time.perf_counter()
    returns = np.asarray(
        jax.jit(episode_returns, static_argnums=0)(env, contexts, jax.random.key(0))
    )
    seconds = time.perf_counter() - start
    print(f"CartPole, a fixed lean-following controller, {EPISODES_PER_LENGTH} episodes per length")
    print(f"{'pole length (m)':>16} {'mean return':>12} {'min':>6} {'max':>6}")
    for length, group in zip(LENGTHS, returns.reshape(len(LENGTHS), -1), strict=True):
        marker = "  <- default" if length == 0.5 else ""
        print(
            f"{length:>16.2f} {group.mean():>12.1f} {group.min():>6.0f} {group.max():>6.0f}{marker}"
        )
    steps = len(lengths) * env.max_steps
    print(f"\n{len(lengths)} episodes ({steps:,} steps) in {seconds:.1f} s including compilation")


if __name__ == "__main__":
    main()
