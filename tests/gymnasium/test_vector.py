"""The vector adapter: per-copy contexts, SAME_STEP auto-reset, parity with CartPole-v1, host envs."""

import gymnasium
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import contextrl as crl
from contextrl.gymnasium import ContextualVectorEnv, HostVectorEnv, make_vector_env

LENGTHS = [{"length": 0.25}, {"length": 1.0}]


def test_make_vec_gives_one_compiled_vector_env_with_per_copy_contexts():
    envs = gymnasium.make_vec(
        "contextrl/CartPole-v0", num_envs=3, contexts=LENGTHS, obs_context_features="varying"
    )
    assert isinstance(envs.unwrapped, ContextualVectorEnv)
    assert envs.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    obs, info = envs.reset(seed=0)
    assert obs.shape == (3, 5) and envs.observation_space.contains(obs)
    # copy i starts at global episode i: contexts 0, 1, 0
    np.testing.assert_array_equal(info["context_id"], [0, 1, 0])
    np.testing.assert_allclose(obs[:, 4], [0.25, 1.0, 0.25])
    np.testing.assert_allclose(info["context"]["length"], [0.25, 1.0, 0.25])
    named = ContextualVectorEnv("CartPole", num_envs=3, contexts={"a": LENGTHS[0], "b": LENGTHS[1]})
    assert named.reset(seed=0)[1]["context_id"].tolist() == ["a", "b", "a"]


def test_same_step_autoreset_keeps_final_obs_and_moves_to_the_next_context():
    envs = ContextualVectorEnv("CartPole", num_envs=3, contexts=LENGTHS)
    envs.reset(seed=1)
    episodes = np.zeros(3, int)
    seen = {copy: [] for copy in range(3)}
    for _ in range(200):
        obs, reward, terminated, truncated, info = envs.step(np.ones(3, int))
        np.testing.assert_array_equal(reward, 1.0)
        for copy in np.flatnonzero(terminated | truncated):
            final = info["final_obs"][copy]
            assert info["_final_obs"][copy] and abs(final[2]) > 0.2 or abs(final[0]) > 2.4
            assert np.all(np.abs(obs[copy]) <= 0.05)  # already the next episode's first obs
            seen[copy].append((info["final_info"]["context_id"][copy], info["context_id"][copy]))
            episodes[copy] += 1
        assert "final_obs" in info or not (terminated | truncated).any()
    assert episodes.min() >= 3
    for copy, pairs in seen.items():
        for episode, (ended, started) in enumerate(pairs):
            # copy i runs global episodes i, i+3, i+6, ... of the round robin over two contexts
            assert ended == (copy + 3 * episode) % 2
            assert started == (copy + 3 * (episode + 1)) % 2


def test_each_copy_follows_cartpole_physics_under_its_own_context():
    lengths = np.array([0.3, 0.5, 1.5, 3.0], np.float32)
    envs = ContextualVectorEnv("CartPole", num_envs=4, contexts=[{"length": v} for v in lengths])
    reference = gymnasium.make("CartPole-v1").unwrapped
    obs, _ = envs.reset(seed=2)
    actions = np.random.default_rng(0).integers(0, 2, (15, 4))
    for step_actions in actions:
        next_obs, _, terminated, truncated, info = envs.step(step_actions)
        for copy in range(4):
            reference.length = float(lengths[copy])
            reference.polemass_length = reference.masspole * reference.length
            reference.state = obs[copy].astype(np.float64)
            expected = reference.step(int(step_actions[copy]))[0]
            actual = (
                info["final_obs"][copy] if terminated[copy] or truncated[copy] else next_obs[copy]
            )
            np.testing.assert_allclose(actual, expected, rtol=1e-5, atol=1e-5)
        obs = next_obs


def test_vector_seeding_is_reproducible_and_resampling_differs_per_copy():
    def run(seed):
        envs = ContextualVectorEnv(
            "CartPole",
            num_envs=8,
            contexts={"length": crl.Uniform(0.1, 2.0)},
            obs_context_features="varying",
        )
        obs, info = envs.reset(seed=seed)
        trace = [obs]
        for _ in range(30):
            trace.append(envs.step(np.zeros(8, int))[0])
        return np.stack(trace), info

    first, info = run(5)
    np.testing.assert_array_equal(first, run(5)[0])
    assert not np.array_equal(first, run(6)[0])
    assert len(np.unique(info["context"]["length"])) == 8
    np.testing.assert_array_equal(info["context_id"], -1)


def test_vector_rejects_bad_input_before_running():
    with pytest.raises(ValueError, match="num_envs"):
        ContextualVectorEnv("CartPole", num_envs=0)
    with pytest.raises(crl.ContextError, match="unknown context feature"):
        ContextualVectorEnv("CartPole", num_envs=2, contexts={"lenght": 0.5})
    envs = ContextualVectorEnv("CartPole", num_envs=2)
    envs.reset(seed=0)
    with pytest.raises(ValueError, match="actions must"):
        envs.step(np.array([0, 2]))


@pytest.mark.parametrize("vectorization", ["sync", "async"])
def test_host_envs_run_as_gymnasium_vector_envs_with_a_context_per_copy(vectorization):
    host_ids = [i for i in crl.registered() if crl.spec(i).host]
    if not host_ids:
        pytest.skip("no host environment is installed")
    env_id = "DmcPointMass" if "DmcPointMass" in host_ids else host_ids[0]
    space = crl.spec(env_id).factory().context_space
    feature = (
        space.features["gravity"]
        if "gravity" in space.names
        else next(iter(space.features.values()))
    )
    values = [feature.default, (feature.default + feature.upper) / 2]
    envs = make_vector_env(
        env_id,
        num_envs=2,
        vectorization=vectorization,
        **({"num_workers": 1} if vectorization == "async" else {}),
        contexts=[{feature.name: v} for v in values],
        obs_context_features="varying",
    )
    assert isinstance(envs, HostVectorEnv)
    assert envs.num_workers == {"sync": 0, "async": 1}[vectorization]
    assert envs.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    obs, info = envs.reset(seed=0)
    np.testing.assert_array_equal(info["context_id"], [0, 1])
    np.testing.assert_allclose(obs[:, -1], values, rtol=1e-6)
    obs, *_ = envs.step(envs.action_space.sample())
    assert envs.observation_space.contains(obs)
    envs.close()


def test_vector_render_draws_each_copy_with_its_context():
    envs = ContextualVectorEnv("CartPole", num_envs=2, contexts=LENGTHS, render_mode="rgb_array")
    envs.reset(seed=0)
    short, long = envs.render()
    assert short.shape == long.shape == (400, 600, 3)
    assert (long != 255).any(axis=2).sum() > (short != 255).any(axis=2).sum()
