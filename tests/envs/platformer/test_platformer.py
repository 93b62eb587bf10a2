"""The platformer: levels from the context, playable by construction, its physics, observations, info."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import contextrl as crl
from contextrl.envs.platformer import level_map
from contextrl.envs.platformer import world as pf

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


@pytest.fixture(scope="module")
def env():
    return crl.make("Platformer")


@pytest.fixture(scope="module")
def step(env):
    return jax.jit(lambda state, action, context: pf.step_physics(state, action, context))


def run(step, state, actions, context):
    """States after each action (a Python list), and the rewards."""
    states, rewards = [], []
    for action in actions:
        state, reward, _ = step(state, action, context)
        states.append(state)
        rewards.append(float(reward))
    return states, rewards


def test_registered_with_carls_name_and_ten_actions(env):
    assert crl.spec("CARLMarioEnv").id == "Platformer"
    assert env.action_space.n == 10 == len(pf.ACTION_NAMES)
    assert pf.ACTION_NAMES[:6] == (
        "noop",
        "down",
        "right",
        "right+run",
        "right+jump",
        "right+run+jump",
    )
    with pytest.raises(ValueError, match="obs must be one of"):
        crl.make("Platformer", obs="rgb")
    with pytest.raises(crl.ContextError, match=r"level_width: value 5000 is outside"):
        env.context(level_width=5000)
    with pytest.raises(crl.ContextError, match="level_index"):
        env.context(level_index="moon")


def test_the_level_depends_only_on_the_context(env):
    ctx = env.context(noise_seed=42, level_index="castle")
    first = level_map(ctx)
    np.testing.assert_array_equal(
        first, level_map(crl.make("Platformer").context(noise_seed=42, level_index="castle"))
    )
    assert not np.array_equal(first, level_map(ctx.replace(noise_seed=43)))
    assert not np.array_equal(first, level_map(ctx.replace(level_index="sky")))
    # Four copies with different keys, over two episodes each, see exactly the same level.
    contexts = env.context_space.stack([ctx] * 4)
    keys = jax.random.split(jax.random.key(0), 4)
    states, first_step = jax.vmap(env.reset)(keys, contexts)
    assert np.all(np.asarray(first_step.obs) == np.asarray(first_step.obs)[0])
    stepper = jax.jit(jax.vmap(env.step))
    observations = []
    for t in range(120):  # walking right into the first gap ends the first episode
        states, ts = stepper(
            jax.random.split(jax.random.key(t), 4), states, jnp.full(4, RIGHT), contexts
        )
        observations.append(np.asarray(ts.obs))
    observations = np.stack(observations)
    assert np.all(observations == observations[:, :1])


def test_jump_and_run_follow_the_hand_computed_physics(env, step):
    ctx = env.default_context()
    start = env.init(jax.random.key(0), ctx)
    states, _ = run(step, start, [9] * 30, ctx)  # jump straight up from the flat start
    heights = np.array([float(s.y) for s in states]) - pf.BASE_HEIGHT
    jump, g = 1.0, 0.12
    n = np.arange(1, 31)
    expected = np.maximum(n * jump - g * n * (n + 1) / 2, 0.0)
    landed = int(np.argmax(expected[1:] == 0)) + 1  # the step that touches the ground again
    np.testing.assert_allclose(heights[:landed], expected[:landed], atol=1e-4)
    heavy = run(step, start, [9] * 30, ctx.replace(gravity=0.2))[0]
    assert max(float(s.y) for s in heavy) < max(float(s.y) for s in states)

    # Running right: the speed approaches run_speed at the rate the inertia allows.
    for inertia in (0.5, 0.89, 1.5):
        c = ctx.replace(mario_inertia=inertia)
        keep = 1 - 0.11 * 0.89 / inertia
        speeds = [float(s.vx) for s in run(step, start, [RIGHT_RUN] * 5, c)[0]]
        np.testing.assert_allclose(speeds, 0.5 * (1 - keep ** np.arange(1, 6)), rtol=1e-5)


def enemy_in_segment(ctx, segment, clock):
    layout = pf.segments(ctx, pf.jump_reach(ctx), jnp.asarray(segment))
    assert bool(layout["enemy"])
    return float(pf.enemy_x(layout, jnp.float32(clock))), float(layout["height"])


def test_enemies_are_stomped_from_above_and_hurt_from_the_side(env, step):
    ctx = env.default_context()  # the default level has an enemy in its first segment
    ex, ey = enemy_in_segment(ctx, 1, 11)
    start = env.init(jax.random.key(0), ctx)
    above = dataclasses.replace(
        start,
        x=jnp.float32(ex),
        y=jnp.float32(ey + 1.0),
        vy=jnp.float32(-0.2),
        on_ground=jnp.bool_(False),
        clock=jnp.int32(10),
    )
    stomped, reward, done = step(above, NOOP, ctx)
    assert bool(pf.is_defeated(stomped.defeated, 1)) and float(stomped.vy) > 0 and not bool(done)

    side = dataclasses.replace(
        start, x=jnp.float32(ex - 0.6), y=jnp.float32(ey), clock=jnp.int32(10)
    )
    small, reward, done = step(side, NOOP, ctx)
    assert bool(small.died) and bool(done) and float(reward) < -pf.DEATH_PENALTY + 1
    large_ctx = ctx.replace(mario_state="large")
    large, reward, done = step(side, NOOP, large_ctx)
    assert (
        not bool(done)
        and int(pf.current_form(large, large_ctx)) == 0
        and int(large.invulnerable) == pf.INVULNERABLE_STEPS
    )
    assert not bool(pf.is_defeated(large.defeated, 1))


def test_the_fire_form_burns_an_enemy_with_a_fireball(env, step):
    ctx = env.context(mario_state="fire")
    ex, ey = enemy_in_segment(ctx, 1, 1)
    start = env.init(jax.random.key(0), ctx)
    assert int(pf.current_form(start, ctx)) == 2
    facing_it = dataclasses.replace(start, x=jnp.float32(ex - 5.0), y=jnp.float32(ey))
    states, _ = run(step, facing_it, [RIGHT_RUN] + [NOOP] * 12, ctx)
    assert int(states[0].fireball_steps) > 0
    assert bool(pf.is_defeated(states[-1].defeated, 1)) and not bool(states[-1].died)
    small = ctx.replace(mario_state="small")
    assert int(run(step, facing_it, [RIGHT_RUN], small)[0][0].fireball_steps) == 0


def test_reward_and_info_at_the_flag_and_in_a_gap(env):
    flat = env.context(level_width=16, gap_frequency=0.0, enemy_density=0.0)
    state, ts = env.reset(jax.random.key(0), flat)
    stepper = jax.jit(env.step)
    total = 0.0
    for t in range(200):
        state, ts = stepper(jax.random.key(t), state, RIGHT_RUN_JUMP, flat)
        total += float(ts.reward)
        if bool(ts.done):
            break
    assert bool(ts.terminated) and bool(ts.info["completed"]) and not bool(ts.info["died"])
    assert float(ts.info["progress"]) == 1.0
    assert total == pytest.approx(float(ts.info["distance"]) + pf.FLAG_BONUS, abs=1e-3)

    gap = env.default_context()  # the default level opens with a gap
    state, ts = env.reset(jax.random.key(0), gap)
    for t in range(200):
        state, ts = stepper(jax.random.key(t), state, RIGHT, gap)
        if bool(ts.done):
            break
    assert bool(ts.info["died"]) and not bool(ts.info["completed"])
    assert float(ts.reward) < -pf.DEATH_PENALTY + 1
    assert 2.0 < float(ts.info["distance"]) < 6.0


def test_tile_observation_shows_the_level_around_the_agent(env):
    ctx = env.default_context()
    obs = np.asarray(env.observe(env.init(jax.random.key(0), ctx), ctx))
    grid = obs[: pf.VIEW_ROWS * pf.VIEW_COLS * 4].reshape(4, pf.VIEW_ROWS, pf.VIEW_COLS)
    level = level_map(ctx)
    column = int(np.floor(pf.START_X + pf.AGENT_WIDTH / 2))
    for r in range(pf.VIEW_ROWS):
        for c in range(pf.VIEW_COLS):
            row, col = pf.BASE_HEIGHT - pf.VIEW_BELOW + r, column - pf.VIEW_BEHIND + c
            inside = 0 <= row < pf.ROWS and 0 <= col
            solid = col < 0 or (inside and level[row, col] in (pf.GROUND, pf.BRICK, pf.PIPE))
            assert grid[0, r, c] == solid, (r, c)
    assert env.observation_space.contains(obs)


def test_pixel_observations_and_full_frames_show_each_style():
    env = crl.make("Platformer", obs="pixels")
    pictures = []
    for style in pf.STYLES:
        ctx = env.context(level_index=style)
        obs = np.asarray(env.observe(env.init(jax.random.key(0), ctx), ctx))
        assert obs.shape == (84 * 84 * 3,) and obs.min() >= 0 and obs.max() <= 1
        pictures.append(obs)
    assert all(not np.array_equal(a, b) for i, a in enumerate(pictures) for b in pictures[i + 1 :])

    import gymnasium

    gym_env = gymnasium.make("contextrl/Platformer-v0", render_mode="rgb_array")
    gym_env.reset(seed=0)
    frame = gym_env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    gym_env.step(RIGHT_RUN)
    for _ in range(10):
        gym_env.step(RIGHT_RUN)
    assert not np.array_equal(frame, gym_env.render())  # the view follows the running agent
    gym_env.close()


def play(env, action, options, steps=300):
    """Holds ``action`` from a reset with ``options`` until the episode ends: the last step's info."""
    env.reset(seed=0, options=options)
    for _ in range(steps):
        _, reward, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            return terminated, reward, info
    raise AssertionError(f"the episode did not end in {steps} steps")


def test_gymnasium_info_says_completed_died_and_distance():
    import gymnasium

    env = gymnasium.make("contextrl/Platformer-v0")
    _, info = env.reset(seed=0)
    assert (info["completed"], info["died"], info["distance"]) == (False, False, 0.0)

    # Walking into the default level's first gap.
    terminated, reward, info = play(env, RIGHT, {"context": {}})
    assert terminated and info["died"] and not info["completed"]
    assert reward < -pf.DEATH_PENALTY + 1 and 2.0 < info["distance"] < 6.0

    # No gaps, an enemy in every underground segment: walking into the first one (this layout has no
    # step or pipe before it that would stop the walk).
    enemies = {
        "level_index": "underground",
        "noise_seed": 2,
        "gap_frequency": 0.0,
        "enemy_density": 2.0,
    }
    terminated, _, info = play(env, RIGHT, {"context": enemies})
    level = level_map(crl.make("Platformer").context(**enemies))
    assert not np.any(level[pf.BASE_HEIGHT - 1] == pf.EMPTY)  # nowhere to fall
    assert terminated and info["died"] and not info["completed"] and info["distance"] < 20

    # A short flat level without enemies: running and jumping reaches the flag.
    flat = {"level_width": 16, "gap_frequency": 0.0, "enemy_density": 0.0}
    terminated, reward, info = play(env, RIGHT_RUN_JUMP, {"context": flat})
    assert terminated and info["completed"] and not info["died"]
    assert info["progress"] == 1.0 and reward > pf.FLAG_BONUS
    env.close()

    # The vector face reports the same facts per copy, the ended episodes' also in final_info.
    envs = gymnasium.make_vec("contextrl/Platformer-v0", num_envs=2)
    envs.reset(seed=0)
    for _ in range(200):
        _, _, terminated, _, info = envs.step(np.full(2, RIGHT))
        if terminated.any():
            break
    assert terminated.all() and info["died"].all() and not info["completed"].any()
    assert np.all(info["final_info"]["died"]) and np.all(info["distance"] > 2.0)
    envs.close()
