"""Gymnasium adapters: single and vector environments with per-episode, per-copy contexts.

import gymnasium, contextrl
env = gymnasium.make("contextrl/CartPole-v0", contexts={"length": 0.8}, obs_context_features="all")
envs = gymnasium.make_vec("contextrl/CartPole-v0", num_envs=64, contexts=batch)
"""

from contextrl.context.schedule import RESAMPLED_ID, ContextSchedule, resolve_contexts
from contextrl.gymnasium.env import ContextualGymEnv
from contextrl.gymnasium.host_vector import HostVectorEnv
from contextrl.gymnasium.registration import gym_id, register_envs
from contextrl.gymnasium.vector import ContextualVectorEnv, make_vector_env

__all__ = [
    "RESAMPLED_ID",
    "ContextSchedule",
    "ContextualGymEnv",
    "ContextualVectorEnv",
    "HostVectorEnv",
    "gym_id",
    "make_vector_env",
    "register_envs",
    "resolve_contexts",
]
