"""PPO learns to finish short platformer levels from the tile observation."""

import jax
import numpy as np

import contextrl as crl
from contextrl.agents import evaluate, ppo


def test_ppo_finishes_short_easy_levels():
    """Four 24-column levels with narrow gaps and no enemies, 60k steps of PPO.

    A level is finished when the deterministic policy's return reaches the distance to the flag plus
    the flag bonus (a death costs 20, so a return above 30 means the flag was reached).
    """
    env = crl.make("Platformer", max_steps=150)
    levels = env.context_space.make(
        level_width=np.full(4, 24), noise_seed=np.arange(4), gap_width=0.3, enemy_density=0.0
    )
    config = ppo.PPOConfig(
        total_timesteps=60_000,
        num_envs=16,
        num_steps=64,
        learning_rate=1e-3,
        hidden_sizes=(64,),
        context_selector="round_robin",
    )
    result = jax.jit(ppo.make_train(config, env, levels))(jax.random.key(0))
    policy = ppo.make_policy(config, env, levels)
    returns = np.asarray(evaluate(policy, result.params, env, levels, 1, jax.random.key(1)))
    assert np.all(returns > 30), returns
    curve = np.asarray(result.metrics["episode_return"])
    assert np.nanmean(curve[:3]) < 25  # it started out failing
