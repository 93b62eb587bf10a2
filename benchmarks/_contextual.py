"""The stepping loop of the benchmarks that time contexts through the core's ``ContextualEnv``
(``step_copies``, each copy with its own context), as a learner's rollout steps them."""

import jax
import jax.numpy as jnp

import contextrl as crl


def contextual_rollout(env, n: int, steps: int, compiler_options=None):
    """jit((key, contexts) → checksum): ``n`` copies through ``ContextualEnv`` for ``steps`` random
    steps; the observations are summed so the compiler cannot drop the simulation."""

    def run(key, contexts):
        contextual = crl.with_contexts(env, contexts)
        reset_key, key = jax.random.split(key)
        state, timestep = contextual.reset_copies(reset_key, n)

        def body(carry, action_key):
            state, total = carry
            actions = jax.vmap(env.action_space.sample)(jax.random.split(action_key, n))
            state, timestep = contextual.step_copies(state, actions)
            return (state, total + jnp.sum(timestep.obs)), None

        start = (state, jnp.sum(timestep.obs))
        (_, total), _ = jax.lax.scan(body, start, jax.random.split(key, steps))
        return total

    return jax.jit(run, compiler_options=compiler_options)
