"""Baseline agents in JAX (PPO, DQN/C51, SAC): each training run is one compiled function.

from contextrl.agents import ppo, evaluate
train = ppo.make_train(ppo.PPOConfig(variant="concat_varying"), env, train_contexts)
result = jax.jit(jax.vmap(train))(jax.random.split(key, 10))      # 10 seeds at once
policy = ppo.make_policy(config, env, train_contexts)
returns = evaluate(policy, params, env, test_contexts, episodes=10, key=key)
"""

from contextrl.agents import dqn, ppo, sac
from contextrl.agents.checkpoint import checkpoint_info, load_checkpoint, save_checkpoint
from contextrl.agents.common import Policy
from contextrl.agents.evaluation import evaluate, evaluate_episodes
from contextrl.agents.networks import VARIANTS
from contextrl.agents.registry import Agent, get_agent, register_agent, registered_agents
from contextrl.agents.saved import SavedPolicy, load_policy
from contextrl.agents.validation import ConfigError

__all__ = [
    "Agent",
    "Policy",
    "SavedPolicy",
    "VARIANTS",
    "ConfigError",
    "checkpoint_info",
    "evaluate",
    "evaluate_episodes",
    "get_agent",
    "load_checkpoint",
    "load_policy",
    "dqn",
    "ppo",
    "register_agent",
    "registered_agents",
    "sac",
    "save_checkpoint",
]
