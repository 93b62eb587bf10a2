"""The dm_control family through the gymnasium single and vector interfaces."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering, before MuJoCo loads

import numpy as np  # noqa: E402
import pytest  # noqa: E402

pytest.importorskip("dm_control")

import gymnasium  # noqa: E402

import contextrl  # noqa: E402  (also registers the gymnasium ids)


def episode(env, seed: int, steps: int) -> tuple[np.ndarray, list]:
    obs, info = env.reset(seed=seed)
    rows, contexts = [obs], [info["context"]]
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, *env.action_space.shape))
    for action in actions.astype(np.float32):
        obs, reward, terminated, truncated, info = env.step(action)
        rows.append(np.append(obs, reward))
        assert not terminated
    return rows, contexts


@pytest.mark.egl
def test_walker_through_gymnasium_with_visible_viscosity_and_a_time_limit_truncation():
    env = gymnasium.make(
        "contextrl/CARLDmcWalkerEnv-v0",
        contexts=[{"viscosity": 0.0}, {"viscosity": 2.0}],
        obs_context_features=["viscosity"],
        max_steps=30,
    )
    assert env.observation_space.shape == (25,)
    obs, info = env.reset(seed=3)
    assert obs[-1] == 0.0 and info["context"]["viscosity"] == 0.0
    assert env.observation_space.contains(obs)
    zero = np.zeros(6, np.float32)
    for step in range(30):
        obs, reward, terminated, truncated, info = env.step(zero)
        assert not terminated and truncated == (step == 29)
    obs, info = env.reset()  # round robin: the second context, written into the model
    assert obs[-1] == pytest.approx(2.0) and info["context"]["viscosity"] == pytest.approx(2.0)
    assert env.unwrapped.contextrl_env.physics.model.opt.viscosity == pytest.approx(2.0)
    frame = env.unwrapped.contextrl_env.render_frame()
    assert frame.ndim == 3 and frame.shape[-1] == 3
    env.close()


def test_same_seed_same_episode_through_gymnasium():
    env = gymnasium.make("contextrl/DmcPointMass-v0", contexts={"mass": 1.0, "target_x": 0.1})
    first, contexts = episode(env, seed=11, steps=20)
    again, _ = episode(env, seed=11, steps=20)
    other, _ = episode(env, seed=12, steps=20)
    np.testing.assert_array_equal(np.concatenate(first[1:]), np.concatenate(again[1:]))
    assert not np.allclose(first[0], other[0])
    assert contexts[0]["mass"] == pytest.approx(1.0)
    env.close()


def test_vector_env_with_two_worker_processes_gives_each_copy_its_context():
    envs = gymnasium.make_vec(
        "contextrl/DmcFinger-v0",
        num_envs=2,
        contexts=[{"spinner_length": 0.18}, {"spinner_length": 0.3}],
        obs_context_features=["spinner_length"],
        num_workers=1,
    )
    assert envs.unwrapped.num_workers == 1  # the second copy steps in a worker process
    obs, info = envs.reset(seed=0)
    np.testing.assert_allclose(obs[:, -1], [0.18, 0.3], rtol=1e-6)
    for _ in range(5):
        obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
    assert obs.shape == (2, 10) and np.all(np.isfinite(obs))
    envs.close()


@pytest.mark.parametrize(
    "name", ["DmcWalker", "DmcQuadruped", "DmcFish", "DmcFinger", "DmcPointMass"]
)
@pytest.mark.filterwarnings("ignore::UserWarning")  # unbounded observations, asymmetric actions
@pytest.mark.egl
def test_gymnasium_check_env_passes_with_resampled_visible_contexts(name):
    from gymnasium.utils.env_checker import check_env

    feature = "mass" if name == "DmcPointMass" else "gravity"
    env = gymnasium.make(
        f"contextrl/{name}-v0",
        contexts={feature: contextrl.Uniform(1.0, 5.0)},
        obs_context_features="all",
        render_mode="rgb_array",
    )
    check_env(env.unwrapped, skip_render_check=False)
    env.close()


def test_render_fps_is_one_frame_per_control_step():
    env = gymnasium.make("contextrl/DmcWalker-v0")
    assert env.metadata["render_fps"] == 40  # walker acts every 25 ms, whatever its physics step
    env.close()
