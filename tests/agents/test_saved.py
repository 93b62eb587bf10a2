"""Saved agents and training metrics as a user meets them: checkpoint names round trip, a saved agent
comes back ready to act, curves never hold NaN, a host environment gets a message that fits."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import contextrl as crl
from contextrl.agents import (
    ConfigError,
    checkpoint_info,
    load_checkpoint,
    load_policy,
    ppo,
    save_checkpoint,
)
from contextrl.agents.common import EpisodeLog
from contextrl.agents.saved import _rebuild_config


def test_checkpoint_names_round_trip_and_rebuild_a_policy(tmp_path):
    env = crl.make("CartPole", max_steps=40)
    space = env.context_space
    contexts = space.stack([space.make(length=0.3), space.make(length=0.7)])
    config = ppo.PPOConfig(variant="concat_varying", hidden_sizes=(8, 8), total_timesteps=4096)
    params = ppo.init_params(config, env, contexts, jax.random.key(3))
    written = save_checkpoint(
        tmp_path / "runs" / "ppo_seed0",
        params,
        config,
        train_contexts=contexts,
        agent="ppo",
        env="CartPole",
        max_steps=40,
    )
    assert written == tmp_path / "runs" / "ppo_seed0.npz"
    for name in ("ppo_seed0", "ppo_seed0.npz"):  # the name given to save loads back
        loaded = load_checkpoint(tmp_path / "runs" / name)
        assert jax.tree_util.tree_structure(loaded) == jax.tree_util.tree_structure(params)
    assert checkpoint_info(tmp_path / "runs" / "ppo_seed0")["metadata"]["agent"] == "ppo"
    with pytest.raises(FileNotFoundError, match="no checkpoint at .*missing.npz"):
        load_checkpoint(tmp_path / "runs" / "missing")

    saved = load_policy(tmp_path / "runs" / "ppo_seed0")
    assert saved.config == config  # a PPOConfig again, hidden_sizes a tuple
    assert saved.env_id == "CartPole" and saved.env.max_steps == 40
    np.testing.assert_allclose(np.asarray(saved.train_contexts.length), [0.3, 0.7])
    # the rebuilt policy acts exactly as one made from the original config and contexts
    original = ppo.make_policy(config, env, contexts)
    obs = jnp.asarray([0.01, -0.02, 0.03, 0.0])
    for length in (0.3, 0.7):
        ctx = space.make(length=length)
        key = jax.random.key(5)
        assert saved.act(obs, ctx, key) == original(params, obs, ctx, key)
    save_checkpoint(tmp_path / "bare", params, config)
    with pytest.raises(ValueError, match="does not name its agent and env"):
        load_policy(tmp_path / "bare")


def test_configs_saved_before_the_variant_rename_load():
    """Checkpoints written when the field was called obs_context rebuild with it as ``variant``."""
    old = {"obs_context": "concat_all", "hidden_sizes": [8, 8], "total_timesteps": 4096}
    config = _rebuild_config(ppo.PPOConfig, old)
    assert config == ppo.PPOConfig(variant="concat_all", hidden_sizes=(8, 8), total_timesteps=4096)


def test_episode_log_curve_is_never_nan():
    """Two copies; values by hand: nothing ended → the running mean; an end → its return; a quiet
    period → the last value again."""
    log = EpisodeLog.create(num_envs=2, capacity=8, num_contexts=2)
    ids = jnp.asarray([0, 1])
    log = log.record(jnp.asarray([1.0, 2.0]), jnp.asarray([False, False]), ids, 2)
    log, row = log.close_period()
    assert float(row["episode_return"]) == 1.5 and float(row["episode_length"]) == 1.0
    assert int(row["episodes_finished"]) == 0
    log = log.record(jnp.asarray([1.0, 1.0]), jnp.asarray([True, False]), ids, 4)
    log, row = log.close_period()
    assert float(row["episode_return"]) == 2.0 and float(row["episode_length"]) == 2.0
    assert float(row["context_return"][0]) == 2.0 and np.isnan(row["context_return"][1])
    log = log.record(jnp.asarray([1.0, 1.0]), jnp.asarray([False, False]), ids, 6)
    log, row = log.close_period()
    assert float(row["episode_return"]) == 2.0 and int(row["episodes_finished"]) == 0
    assert float(row["context_return"][0]) == 2.0  # kept, not NaN


def test_ppo_on_a_host_environment_says_how_to_train_it():
    env = crl.make("DmcWalker")
    contexts = env.context_space.stack([env.context_space.default()])
    with pytest.raises(ConfigError) as error:
        ppo.make_train(ppo.PPOConfig(), env, contexts)
    message = str(error.value)
    assert "DmcWalker is a host environment" in message and "ppo.train_gymnasium" in message
    assert "crl.make(...)" not in message
    env.close()


def test_host_collector_curve_is_never_nan():
    """CartPole pays 1 per step: after two steps with no episode ended the row is the running mean 2;
    after an end, that episode's return; then it is kept while nothing ends."""
    from contextrl.agents.host import HostCollector

    with HostCollector("CartPole", 2, None, seed=0, max_steps=3) as collector:
        for _ in range(2):
            collector.step(np.zeros(2, np.int64))
        row = collector.close_period()
        assert row["episode_return"] == 2.0 and row["episodes_finished"] == 0
        collector.step(np.zeros(2, np.int64))  # the time limit ends both episodes at 3 steps
        row = collector.close_period()
        assert row["episode_return"] == 3.0 and row["episodes_finished"] == 2
        collector.step(np.zeros(2, np.int64))
        row = collector.close_period()
        assert row["episode_return"] == 3.0 and row["episodes_finished"] == 0


def test_host_curve_has_a_return_per_context():
    """The host loop logs episodes in the JAX path's EpisodeLog, so its curve has a return per
    context id, NaN until that context's first episode ends (a time limit of 3: every return is 3)."""
    from contextrl.agents.host import HostCollector

    env = crl.make("CartPole")
    contexts = env.context_space.stack([env.context(length=0.3), env.context(length=0.6)])
    with HostCollector(
        "CartPole", 2, contexts, selector="round_robin", seed=0, max_steps=3
    ) as collector:
        assert np.isnan(collector.close_period()["context_return"]).all()
        for _ in range(3):
            collector.step(np.zeros(2, np.int64))
        row = collector.close_period()
        episodes = collector.episodes()
    np.testing.assert_array_equal(row["context_return"], [3.0, 3.0])
    np.testing.assert_array_equal(episodes["context_id"], [0, 1])
