"""The dm_control family on MJX: from dm_control's own start state, every feature's context steps as
on the reference (observation and reward, float32 tolerances), the starts follow dm_control's rules
(Quadruped's free height, Finger's contact-free draw), and the faces reach it."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering, before MuJoCo loads

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

pytest.importorskip("dm_control")
pytest.importorskip("mujoco.mjx")

import gymnasium  # noqa: E402
import mujoco  # noqa: E402
from mujoco import mjx  # noqa: E402

import contextrl as crl  # noqa: E402
from contextrl.envs.dmc_mjx import DmcState  # noqa: E402
from tests.envs.dmc.test_dmc import changed_value, shared_values  # noqa: E402

DOMAINS = ("DmcWalker", "DmcQuadruped", "DmcFish", "DmcFinger", "DmcPointMass")
STEPS = 10
# float32 against MuJoCo's float64 over STEPS control steps (up to 100 physics steps): the largest
# error measured was 6e-4 (Quadruped's foot force sensors, seen through arcsinh).
TOLERANCE = {"rtol": 2e-3, "atol": 2e-3}


def reference_goal(name: str, env, physics) -> np.ndarray:
    """What the reference's task drew into its model at the reset, as the MJX state holds it."""
    named = physics.named.model
    if name == "DmcFish" and env.task == "swim":
        return np.asarray(named.geom_pos["target"])
    if name == "DmcFinger" and env.task != "spin":
        return np.asarray(named.site_pos["target"])
    return np.zeros(3)


def host_start(name: str, env, host) -> tuple[np.ndarray, ...]:
    """dm_control's state after its reset as the MJX state holds it: qpos, qvel, act and goal."""
    data = host.physics.data
    return (
        data.qpos.copy(),
        data.qvel.copy(),
        data.act.copy(),
        reference_goal(name, env, host.physics),
    )


def mjx_start(env, context, qpos, qvel, act, goal) -> DmcState:
    """The MJX state at a start taken from dm_control (``host_start``)."""
    data = env.stock.blank.replace(qpos=qpos, qvel=qvel, act=act)
    return DmcState(mjx.forward(env.model(context), data), goal)


def feature_rows(host) -> list[tuple[str, dict]]:
    """The default context, then one context per feature the MJX version has, moved off its default."""
    rows = [("default", {})]
    for name in crl.make(host.name, backend="mjx").context_space.names:
        rows.append((name, {**shared_values(host, name), name: changed_value(host, name)}))
    return rows


def run_both(name: str, task: str | None = None):
    """Rows, and (observation, reward) per step and row on dm_control and on MJX from the same start."""
    kwargs = {} if task is None else {"task": task}
    host, env = crl.make(name, **kwargs), crl.make(name, backend="mjx", **kwargs)
    rows = feature_rows(host) if task is None else [("default", {})]
    actions = np.random.default_rng(7).uniform(-1, 1, (STEPS, *env.action_space.shape))
    theirs, starts = [], []
    for _, values in rows:
        host.reset_physics(host.context(**values), np.random.default_rng(3))
        starts.append(host_start(name, env, host))
        steps = [host.step_physics(action)[:2] for action in actions]
        theirs.append(([obs for obs, _ in steps], [reward for _, reward in steps]))
    contexts = jax.tree_util.tree_map(
        lambda *leaves: jnp.stack(leaves), *[env.context(**values) for _, values in rows]
    )
    qpos, qvel, act, goal = (
        jnp.asarray(np.stack(part), jnp.float32) for part in zip(*starts, strict=True)
    )

    def episode(context, *start):
        def step(state, action):
            state, reward, _ = env.transition(None, state, action, context)
            return state, (env.observe(state, context), reward)

        return jax.lax.scan(step, mjx_start(env, context, *start), jnp.asarray(actions))[1]

    ours = jax.jit(jax.vmap(episode))(contexts, qpos, qvel, act, goal)
    their_obs = np.stack([np.stack(obs) for obs, _ in theirs])
    their_reward = np.stack([np.array(reward) for _, reward in theirs])
    return rows, (np.asarray(ours[0]), np.asarray(ours[1])), (their_obs, their_reward)


# In make test: PointMass and Walker (the cheapest programs, one with contacts); the other domains'
# programs take a minute each to compile and run in `make test-slow`, with the other tasks and the
# start-state rules. Every domain's model at its default context is dm_control's (test_dmc_models.py).
EVERY_EDIT = ("DmcPointMass", "DmcWalker")


@pytest.mark.parametrize(
    "name", [n if n in EVERY_EDIT else pytest.param(n, marks=pytest.mark.slow) for n in DOMAINS]
)
def test_every_feature_steps_as_on_dm_control_from_the_same_state(name):
    rows, (obs, reward), (their_obs, their_reward) = run_both(name)
    for row, (label, _) in enumerate(rows):
        np.testing.assert_allclose(obs[row], their_obs[row], err_msg=label, **TOLERANCE)
        np.testing.assert_allclose(reward[row], their_reward[row], err_msg=label, **TOLERANCE)


@pytest.mark.slow
@pytest.mark.parametrize("name, task", [("DmcFinger", "turn_easy"), ("DmcFish", "upright")])
def test_other_tasks_step_as_on_dm_control(name, task):
    _, (obs, reward), (their_obs, their_reward) = run_both(name, task)
    np.testing.assert_allclose(obs, their_obs, **TOLERANCE)
    np.testing.assert_allclose(reward, their_reward, **TOLERANCE)


@pytest.mark.slow
def test_quadruped_starts_at_dm_controls_contact_free_height():
    from dm_control.suite import quadruped

    env = crl.make("DmcQuadruped", backend="mjx")
    keys = jax.random.split(jax.random.key(0), 8)
    states = jax.jit(jax.vmap(env.init, (0, None)))(keys, env.default_context())
    physics = suite_physics("quadruped", "walk")
    for qpos in np.asarray(states.data.qpos):
        quadruped._find_non_contacting_height(physics, qpos[3:7])
        assert physics.named.data.qpos["root"][2] == pytest.approx(qpos[2], abs=1e-6)
        assert np.abs(np.linalg.norm(qpos[3:7]) - 1) < 1e-6


@pytest.mark.slow
def test_finger_starts_touch_nothing_as_dm_control_requires():
    env = crl.make("DmcFinger", backend="mjx")
    keys = jax.random.split(jax.random.key(1), 64)
    states = jax.jit(jax.vmap(env.init, (0, None)))(keys, env.default_context())
    physics = suite_physics("finger", "spin")
    angles = np.asarray(states.data.qpos)
    for qpos in angles:
        physics.data.qpos[:] = qpos
        mujoco.mj_forward(physics.model.ptr, physics.data.ptr)
        assert physics.data.ncon == 0
    assert np.ptp(angles[:, 2]) > 3  # the spinner drawn over its whole turn


def suite_physics(domain: str, task: str):
    from dm_control import suite

    return suite.load(domain, task).physics


def test_faces_and_commands_reach_the_mjx_backend_and_the_default_stays_dm_control():
    from contextrl.core.host import HostEnv

    assert isinstance(crl.make("DmcPointMass"), HostEnv)
    contexts = [{"mass": 0.3}, {"mass": 3.0}]
    env = gymnasium.make("contextrl/DmcPointMass-v0", backend="mjx", contexts=contexts)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (4,) and not isinstance(env.unwrapped.contextrl_env, HostEnv)
    obs, reward, *_ = env.step(np.zeros(2, np.float32))
    assert np.isfinite(obs).all() and np.isfinite(reward)
    from contextrl.carl.envs import CARLDmcPointMassEnv

    carl = CARLDmcPointMassEnv(backend="mjx", contexts={0: {"mass": 1.0}})
    assert not isinstance(carl.unwrapped.contextrl_env, HostEnv)
    vector = gymnasium.make_vec("contextrl/DmcPointMass-v0", num_envs=3, backend="mjx")
    assert type(vector).__name__ == "ContextualVectorEnv"  # one compiled call, no worker processes
    with pytest.raises(ValueError, match=r"backend must be one of \('dm_control', 'mjx'\)"):
        crl.make("DmcWalker", backend="mujoco")
    with pytest.raises(ValueError, match="unknown task 'escape'; on MJX choose one of"):
        crl.make("DmcQuadruped", backend="mjx", task="escape")
    finger = crl.make("DmcFinger", backend="mjx")
    with pytest.raises(crl.ContextError, match="limb_length_0"):
        finger.context(limb_length_0=0.15)
