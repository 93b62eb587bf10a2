"""The one stepping loop every environment benchmark times, so figures compare like with like.

Each of the copies takes uniformly random actions inside one ``lax.scan``; every copy gets its own key
each step (split from one key) and its own parameters (context). The observations are summed so the
compiler cannot drop the simulation.
"""

import os
import time

# One CPU device per core, so a benchmark can also run its copies split over the cores (set before jax
# is imported; single-device figures are unaffected).
CORES = os.cpu_count() or 1
os.environ.setdefault("XLA_FLAGS", f"--xla_force_host_platform_device_count={CORES}")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402


def observing(env):
    """``(reset, step)`` of a JAX env that return ``(state, obs)``, as :func:`random_rollout` takes them."""

    def reset(key, ctx):
        state, ts = env.reset(key, ctx)
        return state, ts.obs

    def step(key, state, action, ctx):
        state, ts = env.step(key, state, action, ctx)
        return state, ts.obs

    return reset, step


def random_rollout(reset, step, sample_action, params, steps: int, devices: int = 1):
    """A compiled function key → checksum: reset every copy, then ``steps`` random steps.

    ``reset(key, p) -> (state, obs)``, ``step(key, state, action, p) -> (state, obs)``; ``params`` is a
    pytree with one leading entry per copy. With ``devices`` > 1 the copies are split evenly over that
    many CPU devices (one per core) and run by one ``pmap``-compiled call.
    """

    def run(key, params):
        n = jax.tree_util.tree_leaves(params)[0].shape[0]
        reset_key, key = jax.random.split(key)
        state, _ = jax.vmap(reset)(jax.random.split(reset_key, n), params)

        def body(carry, _):
            state, key, total = carry
            key, action_key, step_key = jax.random.split(key, 3)
            actions = jax.vmap(sample_action)(jax.random.split(action_key, n))
            state, obs = jax.vmap(step)(jax.random.split(step_key, n), state, actions, params)
            return (state, key, total + jnp.sum(obs)), None

        (_, _, total), _ = jax.lax.scan(body, (state, key, jnp.zeros(())), None, steps)
        return total

    if devices == 1:
        compiled = jax.jit(run)
        return lambda key: compiled(key, params)
    shards = jax.tree_util.tree_map(lambda x: x.reshape(devices, -1, *x.shape[1:]), params)
    compiled = jax.pmap(run, devices=jax.devices()[:devices])
    return lambda key: compiled(jax.random.split(key, devices), shards)


def batched_rollout(reset_batch, step_batch, num_actions: int, steps: int, shards=None):
    """A compiled function key → checksum over whole batches: how a batched API is used.

    ``reset_batch(key) -> (state, obs)`` starts every copy; ``step_batch(key, state, actions) ->
    (state, obs)`` steps them all. Actions are uniform over ``num_actions``, one draw per step for the
    whole batch. Each library gets the per-copy keys it needs its own way (gymnax: a split per copy per
    step; contextrl's ``step_copies``: from the state, none per step). With ``shards`` (a pytree with
    one leading entry per CPU device) each device runs its own batch, one ``pmap``-compiled call, and
    both functions take the device's shard as a last argument.
    """

    def run(key, *shard):
        reset_key, key = jax.random.split(key)
        state, obs = reset_batch(reset_key, *shard)
        n = obs.shape[0]

        def body(carry, _):
            state, key, total = carry
            key, action_key, step_key = jax.random.split(key, 3)
            actions = jax.random.randint(action_key, (n,), 0, num_actions)
            state, obs = step_batch(step_key, state, actions, *shard)
            return (state, key, total + jnp.sum(obs)), None

        (_, _, total), _ = jax.lax.scan(body, (state, key, jnp.zeros(())), None, steps)
        return total

    if shards is None:
        return jax.jit(run)
    devices = jax.tree_util.tree_leaves(shards)[0].shape[0]
    compiled = jax.pmap(run, devices=jax.devices()[:devices])
    return lambda key: compiled(jax.random.split(key, devices), shards)


def steps_per_second(run, n: int, steps: int, repeats: int = 3) -> tuple[float, float]:
    """(compile seconds, best steps/s over ``repeats`` timed calls)."""
    start = time.perf_counter()
    run(jax.random.key(0)).block_until_ready()
    compile_seconds = time.perf_counter() - start
    best = float("inf")
    for i in range(repeats):
        start = time.perf_counter()
        run(jax.random.key(i + 1)).block_until_ready()
        best = min(best, time.perf_counter() - start)
    return compile_seconds, n * steps / best
