"""The platformer: levels from the context, playable by construction, its physics, observations, info."""


import jax
import jax.numpy as jnp
import numpy as np

import contextrl as crl
from contextrl.envs.platformer import level_map
from contextrl.envs.platformer import platformer as pf

RIGHT, RIGHT_RUN, RIGHT_JUMP, RIGHT_RUN_JUMP, NOOP, LEFT = 2, 3, 4, 5, 0, 6
MACROS = jnp.array([RIGHT_RUN, RIGHT_RUN_JUMP, NOOP, LEFT, RIGHT, RIGHT_JUMP])
MACRO_STEPS = 4


def beam_search(context, rounds: int, beam: int = 48):
    """Whether a beam search over the environment's own step reaches the flag of ``context``'s level.

    Each round every kept state tries each macro action (one action held for MACRO_STEPS steps); states
    that die are dropped, and the ``beam`` furthest right are kept, at most one per (x, y) half-tile cell
    so the beam keeps alternatives (waiting for an enemy to walk away, jumping earlier or later).
    """
    env = crl.make("Platformer")
    start = env.init(jax.random.key(0), context)
    states = jax.tree_util.tree_map(lambda leaf: jnp.stack([leaf] * beam), start)
    alive = jnp.arange(beam) == 0

    def macro(state, action):
        def body(carry, _):
            state, dead, done = carry
            nxt, _, _ = pf.step_physics(state, action, context)
            nxt = jax.tree_util.tree_map(lambda a, b: jnp.where(dead | done, a, b), state, nxt)
            return (nxt, dead | nxt.died, done | nxt.completed), None

        (state, dead, done), _ = jax.lax.scan(
            body, (state, jnp.bool_(False), jnp.bool_(False)), None, MACRO_STEPS
        )
        return state, dead, done

    def round_(carry, _):
        states, alive, solved = carry
        expanded = jax.vmap(lambda s: jax.vmap(lambda a: macro(s, a))(MACROS))(states)
        children, dead, done = jax.tree_util.tree_map(
            lambda leaf: leaf.reshape(-1, *leaf.shape[2:]), expanded
        )
        ok = jnp.repeat(alive, len(MACROS)) & ~dead
        solved = solved | jnp.any(ok & done)
        cell = jnp.round(children.x * 2) * 1000 + jnp.round(children.y * 2)
        score = jnp.where(ok, children.x, -jnp.inf)
        order = jnp.lexsort((-score, cell))  # by cell, best first within a cell
        first = jnp.concatenate([jnp.array([True]), cell[order][1:] != cell[order][:-1]])
        unique_score = (
            jnp.full_like(score, -jnp.inf).at[order].set(jnp.where(first, score[order], -jnp.inf))
        )
        best = jnp.argsort(-unique_score)[:beam]
        kept = jax.tree_util.tree_map(lambda leaf: leaf[best], children)
        return (kept, jnp.isfinite(unique_score[best]), solved), None

    (_, _, solved), _ = jax.lax.scan(round_, (states, alive, jnp.bool_(False)), None, rounds)
    return solved


def physics_contexts(n: int, key):
    """Contexts with every physics and difficulty feature drawn across its bounds, all four styles."""
    env = crl.make("Platformer")
    space = env.context_space
    keys = jax.random.split(key, 8)

    def across(i, name):
        f = space.features[name]
        return jax.random.uniform(keys[i], (n,), minval=f.lower, maxval=f.upper)

    return space.make(
        level_width=np.full(n, 48),
        level_index=np.arange(n) % 4,
        noise_seed=np.arange(n) * 7919 + 1,
        gap_width=np.asarray(across(0, "gap_width")),
        gap_frequency=np.asarray(across(1, "gap_frequency")),
        enemy_density=np.asarray(jax.random.uniform(keys[2], (n,))),
        platform_height_variation=np.asarray(across(3, "platform_height_variation")),
        mario_inertia=np.asarray(across(4, "mario_inertia")),
        gravity=np.asarray(across(5, "gravity")),
        jump_speed=np.asarray(across(6, "jump_speed")),
        run_speed=np.asarray(across(7, "run_speed")),
    )


def test_every_generated_level_is_playable_by_its_own_physics():
    """Reachability over many seeds: a search over the real step reaches every flag (small form)."""
    contexts = physics_contexts(48, jax.random.key(1))
    solved = jax.jit(jax.vmap(lambda c: beam_search(c, rounds=110)))(contexts)
    reach = jax.vmap(pf.jump_reach)(contexts)
    assert np.all(np.asarray(solved)), np.flatnonzero(~np.asarray(solved))
    # The levels were not trivial: gaps, steps and pipes were there to be cleared.
    assert int(np.sum(np.asarray(reach["gap"]) >= 2)) >= 10
    maps = [level_map(contexts[i]) for i in range(len(contexts))]
    assert sum(int(np.sum(m[pf.BASE_HEIGHT - 1] == pf.EMPTY)) > 0 for m in maps) >= 20
    assert sum(int(np.sum(m == pf.PIPE)) > 0 for m in maps) >= 10
