"""Steps per second of the platformer: thousands of copies, each on its own generated level.

    python benchmarks/bench_platformer.py [--quick]

Every figure steps the copies through the project's one stepping path, ``ContextualEnv.step_copies``
(random actions, same-step auto-reset, each copy keeping its own level: a round robin over as many
contexts as copies). It prints tile observations at 4,096 copies (also split over every core, each
core's ``step_copies`` over its share), pixel observations at 256 and 4,096 copies (frames/s), and
what the level costs: the same loop with the level generator swapped for flat ground without enemies,
and a reset of every copy against a step.
CARL's Mario (Java over py4j, TOAD-GAN) is not run here (it needs Java, Xvfb and torch 2.4); its ~230
steps/s are the figure the CARL authors report, quoted for scale.
"""

import argparse
import time

import jax
import jax.numpy as jnp
from _scan import CORES, batched_rollout, steps_per_second

import contextrl as crl
from contextrl.envs.platformer import world

CARL_MARIO_STEPS_PER_SECOND = 230  # reported by CARL (FAMILIES.md), not measured here


def levels(env, n):
    """``n`` copies on ``n`` different levels: every seed, all four styles, widths 64 … 1,000."""
    keys = jax.random.split(jax.random.key(0), 2)
    return env.context_space.make(
        noise_seed=jnp.arange(n),
        level_index=jnp.arange(n) % 4,
        level_width=jax.random.randint(keys[0], (n,), 64, 1001),
        enemy_density=jax.random.uniform(keys[1], (n,), maxval=2.0),
    )


def measure(env, n, steps, devices=1):
    """(compile s, steps/s) of ``step_copies`` over ``n`` copies, copy i on level i; with ``devices``
    > 1 the copies are split evenly over that many CPU devices (one per core), each stepping its share
    through its own ``step_copies``."""

    def reset_batch(key, contexts):
        state, ts = crl.with_contexts(env, contexts).reset_copies(key, n // devices)
        return state, ts.obs

    def step_batch(_, state, actions, contexts):
        state, ts = crl.with_contexts(env, contexts).step_copies(state, actions)
        return state, ts.obs

    shards = jax.tree_util.tree_map(lambda x: x.reshape(devices, -1, *x.shape[1:]), levels(env, n))
    run = batched_rollout(reset_batch, step_batch, 10, steps, shards)
    return steps_per_second(run, n, steps)


def reset_and_step_seconds(env, n, repeats=20):
    """Seconds of one reset of ``n`` copies and of one step of them (``jax.vmap``, compiled alone)."""
    contexts = levels(env, n)
    keys = jax.random.split(jax.random.key(0), n)
    reset = jax.jit(jax.vmap(env.reset))
    step = jax.jit(jax.vmap(env.step))
    state, _ = reset(keys, contexts)
    actions = jax.random.randint(jax.random.key(1), (n,), 0, 10)

    def best(call):
        jax.block_until_ready(call())
        fastest = float("inf")
        for _ in range(repeats):
            start = time.perf_counter()
            jax.block_until_ready(call())
            fastest = min(fastest, time.perf_counter() - start)
        return fastest

    return best(lambda: reset(keys, contexts)), best(lambda: step(keys, state, actions, contexts))


def flat_segments(context, reach, segment):
    """Segments without gaps, pipes, bricks or enemies: the level without its generator."""
    zeros = jnp.zeros(jnp.shape(segment), jnp.int32)
    return {
        "gap": zeros,
        "height": zeros + world.BASE_HEIGHT,
        "pipe_height": zeros,
        "pipe_at": zeros,
        "bricks": zeros.astype(bool),
        "brick_row": zeros,
        "enemy": zeros.astype(bool),
        "patrol_from": zeros.astype(jnp.float32),
        "patrol_span": zeros.astype(jnp.float32) + 1,
        "phase": zeros.astype(jnp.float32),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer steps")
    args = parser.parse_args()
    steps = 50 if args.quick else 200
    print(f"jax {jax.__version__} on {jax.devices()[0].platform}, {steps} random steps per copy\n")

    tiles = crl.make("Platformer")
    print("Tile observations, every copy on its own level (ContextualEnv.step_copies)")
    print(f"{'copies':>8} {'devices':>8} {'compile s':>10} {'steps/s':>12} {'× CARL Mario':>14}")
    compile_s, full = measure(tiles, 4096, steps)
    print(
        f"{4096:>8} {1:>8} {compile_s:>10.1f} {full:>12.3g} {full / CARL_MARIO_STEPS_PER_SECOND:>14.0f}"
    )
    if CORES > 1:
        compile_s, split = measure(tiles, 4096, steps, CORES)
        print(
            f"{4096:>8} {CORES:>8} {compile_s:>10.1f} {split:>12.3g} {split / CARL_MARIO_STEPS_PER_SECOND:>14.0f}"
        )

    pixels = crl.make("Platformer", obs="pixels")
    print("\nPixel observations (84×84 RGB drawn in JAX), every copy on its own level")
    print(f"{'copies':>8} {'compile s':>10} {'frames/s':>12} {'× CARL Mario':>14}")
    for n in (256, 4096):
        compile_s, rate = measure(pixels, n, max(4, steps // 40))
        print(
            f"{n:>8} {compile_s:>10.1f} {rate:>12.3g} {rate / CARL_MARIO_STEPS_PER_SECOND:>14.0f}"
        )

    # The level is no state: a step generates the segments around the agent from the context hash.
    # Swapping the generator for flat ground shows what that costs.
    generated = world.segments
    world.segments = flat_segments
    try:
        flat = measure(crl.make("Platformer"), 4096, steps)[1]
    finally:
        world.segments = generated
    reset_s, step_s = reset_and_step_seconds(tiles, 4096)
    print("\nThe level's cost (tile observations, 4,096 copies, one device)")
    print(f"generated levels {full:.3g} steps/s, flat ground {flat:.3g} steps/s")
    print(
        f"generation's share of a step: {1 - full / flat:.0%} (it runs in every step: no level is stored)"
    )
    print(
        f"reset of every copy {reset_s * 1e3:.2f} ms, a step {step_s * 1e3:.2f} ms "
        f"(a reset generates nothing: the first observation reads the level like a step)"
    )


if __name__ == "__main__":
    main()
