"""Stable-Baselines3 PPO on contextrl's gymnasium CartPole with a new pole length every episode.

The pole length is drawn from U(0.25, 0.75) m at every reset and shown to the agent (the observation
is CartPole's four numbers plus the normalised length), then the policy is evaluated at the default
context (length 0.5). Runs in a few minutes on two CPU cores:

    python examples/sb3_ppo_cartpole.py --timesteps 100000
"""

from __future__ import annotations

import argparse

import gymnasium
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env

import contextrl as crl  # noqa: F401  (registers contextrl/<Id>-v0 with gymnasium)

TRAIN_CONTEXTS = {"length": crl.Uniform(0.25, 0.75)}
VISIBLE = {"obs_context_features": ["length"], "obs_context_normalize": True}


def linear(start: float):
    """A schedule that decays linearly from ``start`` to 0 over training (SB3's progress_remaining)."""
    return lambda progress_remaining: progress_remaining * start


def train(timesteps: int = 100_000, seed: int = 0) -> PPO:
    """PPO with RL Zoo's CartPole hyper-parameters, on eight copies that resample the pole length."""
    envs = make_vec_env(
        "contextrl/CartPole-v0",
        n_envs=8,
        seed=seed,
        env_kwargs={"contexts": TRAIN_CONTEXTS, **VISIBLE},
    )
    model = PPO(
        "MlpPolicy",
        envs,
        n_steps=32,
        batch_size=256,
        gae_lambda=0.8,
        gamma=0.98,
        n_epochs=20,
        ent_coef=0.0,
        learning_rate=linear(1e-3),
        clip_range=linear(0.2),
        seed=seed,
        device="cpu",
    )
    return model.learn(total_timesteps=timesteps)


def evaluate(model: PPO, context: dict | None = None, episodes: int = 5, seed: int = 100) -> float:
    """Mean return of the greedy policy under one fixed context (default: the original CartPole)."""
    env = gymnasium.make("contextrl/CartPole-v0", contexts=context, **VISIBLE)
    returns = []
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        done, total = False, 0.0
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(int(action))
            total += reward
            done = terminated or truncated
        returns.append(total)
    return float(np.mean(returns))


def main(argv=None) -> float:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timesteps", type=int, default=100_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)  # small networks: one thread is fastest and leaves the other core free
    model = train(args.timesteps, args.seed)
    for length in (0.25, 0.5, 0.75):
        print(f"length {length:.2f}: mean return {evaluate(model, {'length': length}):.1f}")
    score = evaluate(model)
    print(f"default context: mean return {score:.1f}")
    return score


if __name__ == "__main__":
    main()
