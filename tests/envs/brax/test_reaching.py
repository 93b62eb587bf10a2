"""The paper's target-reaching tasks rebuilt on MJX (Fetch, Grasp, UR5e): the CARL failures cannot
happen, targets are drawn, reached and moved as the paper's tasks did, Grasp's claw picks up and carries
its object, and the tasks are registered under CARL's names and gymnasium ids, rendered and described
(the public checker: test_reaching_checker.py, and Grasp's here, so the suite's two workers share
the three checker runs)."""

import importlib.util

import gymnasium
import numpy as np
import pytest

# Checked without importing brax: brax imports MuJoCo, which must see MUJOCO_GL=egl (set by the family).
if importlib.util.find_spec("brax") is None:
    pytest.skip("brax is not installed", allow_module_level=True)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import contextrl as crl  # noqa: E402
from contextrl import ContextError  # noqa: E402
from contextrl.cli import main  # noqa: E402
from contextrl.core.env import EnvState  # noqa: E402
from contextrl.envs import brax as family  # noqa: E402
from contextrl.envs.brax.reaching import TargetState  # noqa: E402
from contextrl.gymnasium import gym_id  # noqa: E402
from contextrl.testing import check_env  # noqa: E402


def _rollout(env, contexts, steps=30):
    """Observations of one vmapped batch under ``contexts``, every copy given the same random actions."""
    size = env.action_space.shape[0]
    actions = jax.random.uniform(jax.random.key(1), (steps, size), minval=-1, maxval=1)

    def one(context):
        state = env.init(jax.random.key(0), context)

        def body(state, action):
            state, _, _ = env.transition(jax.random.key(2), state, action, context)
            return state, env.observe(state, context)

        return jax.lax.scan(body, state, actions)[1]

    return np.asarray(jax.jit(jax.vmap(one))(env.context_space.stack(contexts)))


def test_carl_failures_cannot_happen_contexts_reach_the_physics_of_each_copy():
    """CARL 0.x wrote these tasks' contexts to a wrapper the jitted step never read, one context per
    batch; here gravity, friction and torso mass each change their own copy of one vmapped batch."""
    env = family.Fetch()
    contexts = [
        env.default_context(),
        env.context(gravity=2.0),
        env.context(friction=0.05),
        env.context(torso_mass=5.0),
        env.default_context(),
    ]
    obs = _rollout(env, contexts)
    for changed in (1, 2, 3):
        assert not np.allclose(obs[0], obs[changed]), contexts[changed]
    np.testing.assert_array_equal(obs[0], obs[4])


def test_carl_ur5e_torso_mass_sets_the_wrist_not_the_frozen_floor():
    """CARL 0.x's UR5e wrote torso_mass into the floor, a frozen body it could not move. Here it is
    the mass of the arm's last link (the original task's "torso"), and only that: the public checker
    (test_reaching_checker.py) shows it changes the motion."""
    env = family.Ur5e()
    stock, system = env.stock_system, env.system(env.context(torso_mass=5.0))
    wrist = stock.link_names.index("wrist_3_link") + 1  # MuJoCo's body 0 is the world
    changed = np.flatnonzero(np.asarray(system.body_mass) != np.asarray(stock.body_mass))
    assert changed.tolist() == [wrist] and float(system.body_mass[wrist]) == 5.0


def test_targets_are_drawn_beyond_the_radius_within_the_distance():
    env = family.Fetch()
    context = env.context(target_distance=3.0, target_radius=0.5)
    keys = jax.random.split(jax.random.key(0), 512)
    targets = jax.jit(jax.vmap(lambda key: env.target(env.init(key, context), context)))(keys)
    targets = np.asarray(targets)
    distance = np.linalg.norm(targets[:, :2], axis=1)
    assert 0.5 <= distance.min() < 0.6 and 3.4 < distance.max() <= 3.5
    angle = np.arctan2(targets[:, 1], targets[:, 0])
    assert np.histogram(angle, bins=4, range=(-np.pi, np.pi))[0].min() > 90  # every quadrant
    np.testing.assert_array_equal(targets[:, 2], 1.0)  # Fetch's targets float 1 m up


def _step_with_wrist_lifted(env):
    """A compiled UR5e step from joint angles that put the wrist at the targets' height (shoulder
    lifted, leaning toward +x) and given target draws: the timestep, the next draws, the wrist."""
    from brax.mjx import pipeline

    @jax.jit
    def step(draws, context):
        q = jnp.zeros(6).at[1].set(1.195)  # wrist at z ≈ 0.163 + 0.917·cos(1.195) ≈ 0.5
        physics = pipeline.init(env.system(context), q, jnp.zeros(6))
        state = EnvState(TargetState(physics, draws, jnp.asarray(0)), jnp.asarray(0))
        after, timestep = env.step(jax.random.key(1), state, jnp.zeros(6), context)
        wrist = env.effector_position(after.physics.pipeline_state)
        return timestep, after.physics.target_draws, wrist

    return step


def _draws_at(point, context):
    """The target draws that put the target right under ``point`` (x, y)."""
    horizontal = np.hypot(point[0], point[1])
    fraction = (horizontal - float(context.target_radius)) / float(context.target_distance)
    return jnp.array([fraction, np.arctan2(point[1], point[0]), 0.0], jnp.float32)


def test_a_reached_target_pays_counts_and_moves():
    """UR5e's reward is 0.1 × progress + 1 on reaching; the reached target moves to a fresh draw and
    ``targets_reached`` counts it. A target 5 cm off, with a 1 cm radius, is not reached."""
    env = family.Ur5e()
    step = _step_with_wrist_lifted(env)
    context = env.context(gravity=0.1, target_distance=1.0, target_radius=0.06)
    _, _, wrist = step(jnp.zeros(3), context)  # where the wrist ends (the target does not move it)
    wrist = np.asarray(wrist)
    assert abs(wrist[2] - 0.5) < 0.05  # the wrist really is at the targets' height
    draws = _draws_at(wrist, context)
    timestep, after, _ = step(draws, context)
    assert 0.99 < float(timestep.reward) < 1.1 and int(timestep.info["targets_reached"]) == 1
    assert not np.array_equal(after, draws)

    tight = env.context(gravity=0.1, target_distance=1.0, target_radius=0.01)
    off = _draws_at(wrist, tight).at[0].add(0.05)  # 5 cm farther out than the wrist
    missed, kept, _ = step(off, tight)
    assert float(missed.reward) < 0.5 and int(missed.info["targets_reached"]) == 0
    np.testing.assert_array_equal(kept, off)


def _grasp_and_carry(env):
    """A compiled scripted Grasp episode (draws, context) → (object positions, targets reached): the
    open claw goes down onto the object, closes (proximal joints 45° in, middle 67.5°, distal 90°),
    lifts it, and carries it toward +x."""
    closed = jnp.tile(jnp.array([1.0, 0.5, 1.0]), 4)

    def action(t):
        fingers = jnp.where(t < 20, -jnp.ones(12), closed)
        palm_x = jnp.where(t < 90, 0.0, 0.5)  # toward x = 5
        palm_z = jnp.where(t < 60, -1.0, 0.0)  # down to 3.5, then up toward 8.5
        return jnp.concatenate([fingers, jnp.stack([palm_x, 0.0, palm_z])])

    @jax.jit
    def episode(draws, context):
        state = env.init(jax.random.key(0), context)
        state = TargetState(state.pipeline_state, draws, state.hits)

        def body(state, t):
            state, _, _ = env.transition(jax.random.key(1), state, action(t), context)
            return state, env.effector_position(state.pipeline_state)

        state, held = jax.lax.scan(body, state, jnp.arange(110))
        return held, state.hits

    return episode


def test_the_claw_picks_up_the_object_and_carries_it_to_a_target():
    """Grasp's claw closes on the object, lifts it and carries it; a target placed on that path is
    reached (the object within ``target_radius``) and counted. With servos of gain 1 instead of 300
    the claw cannot close and the object stays on the floor."""
    env = family.Grasp()
    episode = _grasp_and_carry(env)
    context = env.default_context()
    held, hits = episode(jnp.zeros(3), context)
    held = np.asarray(held)
    assert held[59, 2] < 1.5 and held[89, 2] > 3.5 and int(hits) == 0  # lifted from the floor
    assert held[100, 0] > 1.5  # carried toward +x
    # a target where the object passes at step 100: along +x beyond the radius, at its height
    passed = held[100]
    draws = jnp.array(
        [
            (np.hypot(passed[0], passed[1]) - float(context.target_radius))
            / float(context.target_distance),
            np.arctan2(passed[1], passed[0]),
            passed[2] / float(context.target_height),
        ]
    )
    _, hits = episode(draws, context)
    assert int(hits) >= 1
    weak, _ = episode(jnp.zeros(3), env.context(actuator_strength=1.0))
    assert np.asarray(weak)[:, 2].max() < 1.5


@pytest.mark.slow  # the checker's probes on Grasp's program; its physics: the tests above
def test_public_checker_passes_on_grasp():
    """The full checker, each feature probed in 64 (context pair, key) runs of 10 random steps. The
    fewest runs showing a declared effect, measured under the suite's flags: 51 of 64
    (target_radius's goal effect; the same at 20 steps); friction 64 (the claw starts standing on its
    fingertips)."""
    check_env(family.Grasp(max_steps=10), num_contexts=4, steps=9)


def test_grasp_targets_are_drawn_up_to_the_target_height():
    env = family.Grasp()
    context = env.context(target_height=4.0)
    keys = jax.random.split(jax.random.key(0), 512)
    targets = jax.jit(jax.vmap(lambda key: env.target(env.init(key, context), context)))(keys)
    heights = np.asarray(targets)[:, 2]
    assert 0.0 <= heights.min() < 0.1 and 3.9 < heights.max() <= 4.0


def test_registered_under_carl_names_and_gymnasium_ids_rendered_and_described(capsys):
    for name in ("Fetch", "Grasp", "Ur5e"):
        assert crl.spec(f"CARL{name}").id == name
    with pytest.raises(ValueError, match="MJX only"):
        family.Fetch(backend="spring")
    for name in ("Fetch", "CARLFetch", "Grasp", "CARLGrasp", "Ur5e", "CARLUr5e"):
        assert gym_id(name) in gymnasium.registry

    ur5e = family.Ur5e()
    state = jax.jit(ur5e.init)(jax.random.key(0), ur5e.default_context())
    large = ur5e.render_state(state, ur5e.context(target_radius=0.3))
    small = ur5e.render_state(state, ur5e.context(target_radius=0.05))
    assert large.ndim == 3 and large.std() > 0
    # the target is drawn as a sphere of the context's radius: more of the frame is red
    redness = [np.mean((f[..., 0] > 150) & (f[..., 1] < 120)) for f in (large, small)]
    assert redness[0] > redness[1], redness

    assert main(["describe", "Ur5e"]) == 0
    out = capsys.readouterr().out
    assert "Not offered" in out and "angular_damping" in out and "joint_stiffness:" in out
    # a context naming one is refused with the same reason, on the gymnasium face too
    with pytest.raises(ContextError, match="'angular_damping' is left out of Ur5eContext: MJX"):
        ur5e.context(angular_damping=-0.05)
    with pytest.raises(ContextError, match="'joint_stiffness' is left out of Ur5eContext"):
        gymnasium.make(gym_id("Ur5e"), contexts={"joint_stiffness": 40000.0})
