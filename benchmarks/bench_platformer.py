"""Steps per second of the platformer: thousands of copies, each on its own generated level.

    python benchmarks/bench_platformer.py [--quick]

Prints tile observations at 4,096 copies (one core, and split over every core), pixel observations at
256 and 4,096 copies (frames/s), and the share of a step spent generating the level: the same loop with
the level generator swapped for flat ground without enemies. CARL's Mario (Java over py4j, TOAD-GAN) is
not run here (it needs Java, Xvfb and torch 2.4); its ~230 steps/s are the figure the CARL authors
report, quoted for scale.
"""

import argparse

import jax
import jax.numpy as jnp
from _scan import CORES, random_rollout, steps_per_second

import contextrl as crl
from contextrl.envs.platformer import platformer

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
    def reset(key, ctx):
        state, ts = env.reset(key, ctx)
        return state, ts.obs

    def step(key, state, action, ctx):
        state, ts = env.step(key, state, action, ctx)
        return state, ts.obs

    run = random_rollout(reset, step, env.action_space.sample, levels(env, n), steps, devices)
    return steps_per_second(run, n, steps)


def flat_tiles(context, reach, columns, rows):
    """Flat ground everywhere: the level without its generator (for the generation share)."""
    kind = jnp.where(rows < platformer.BASE_HEIGHT, platformer.GROUND, platformer.EMPTY)
    return jnp.broadcast_to(kind, jnp.broadcast_shapes(jnp.shape(columns), jnp.shape(rows)))


def flat_segments(context, reach, segment):
    """Segments without gaps, pipes, bricks or enemies."""
    zeros = jnp.zeros(jnp.shape(segment), jnp.int32)
    return {
        "gap": zeros,
        "height": zeros + platformer.BASE_HEIGHT,
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
    print("Tile observations, every copy on its own level")
    print(f"{'copies':>8} {'devices':>8} {'compile s':>10} {'steps/s':>12} {'× CARL Mario':>14}")
    rows = [(4096, 1)] + ([(4096, CORES)] if CORES > 1 else [])
    for n, devices in rows:
        compile_s, rate = measure(tiles, n, steps, devices)
        ratio = rate / CARL_MARIO_STEPS_PER_SECOND
        print(f"{n:>8} {devices:>8} {compile_s:>10.1f} {rate:>12.3g} {ratio:>14.0f}")
    full = measure(tiles, 4096, steps)[1]

    pixels = crl.make("Platformer", obs="pixels")
    print("\nPixel observations (84×84 RGB drawn in JAX), every copy on its own level")
    print(f"{'copies':>8} {'compile s':>10} {'frames/s':>12} {'× CARL Mario':>14}")
    for n in (256, 4096):
        compile_s, rate = measure(pixels, n, max(10, steps // 10))
        ratio = rate / CARL_MARIO_STEPS_PER_SECOND
        print(f"{n:>8} {compile_s:>10.1f} {rate:>12.3g} {ratio:>14.0f}")

    # The level is generated where it is looked at (collisions, the observation window), not stored:
    # swap the generator for flat ground and the difference is what generation costs.
    generated = platformer.tiles, platformer.segments
    platformer.tiles = flat_tiles
    platformer.segments = flat_segments
    try:
        flat = measure(crl.make("Platformer"), 4096, steps)[1]
    finally:
        platformer.tiles, platformer.segments = generated
    share = 1 - full / flat
    print("\nLevel generation (tile observations, 4,096 copies, one device)")
    print(f"generated levels {full:.3g} steps/s, flat ground {flat:.3g} steps/s")
    print(
        f"generation's share of the step: {share:.0%} (a reset regenerates nothing: no level is stored)"
    )


if __name__ == "__main__":
    main()
