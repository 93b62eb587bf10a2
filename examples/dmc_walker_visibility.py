"""The paper's visibility experiment on DmcWalker: SAC with the medium's viscosity hidden or visible.

The paper (§6.3) trains on CARLDmcWalker with the viscosity varied at every episode and finds the agent
that sees it learns faster, more stably and better. Here the training viscosity is drawn from
U(1, 2.5) Pa·s at every reset (the paper's factors taken as absolute values: the stock walker has no
medium, so "1 to 2.5 times the default" would be 0 throughout). Two variants train with
Stable-Baselines3 SAC (the paper's SAC settings where SB3 has them), for each seed:
``hidden`` (the walker's 24 numbers) and ``visible`` (plus the normalised viscosity). Each is then
tested on held-out viscosities drawn from the same distribution, one episode each.

Paper scale (hours on CPU):   python examples/dmc_walker_visibility.py --timesteps 500000 --seeds 5
A quick run (a few minutes):  python examples/dmc_walker_visibility.py --timesteps 5000 --max-steps 200
"""

from __future__ import annotations

import argparse

import gymnasium
import numpy as np
import torch
from stable_baselines3 import SAC

import contextrl as crl

LOW, HIGH = 1.0, 2.5
TRAIN_CONTEXTS = {"viscosity": crl.Uniform(LOW, HIGH)}
VARIANTS = {
    "hidden": {},
    "visible": {"obs_context_features": ["viscosity"], "obs_context_normalize": True},
}


def make_env(variant: str, contexts, max_steps: int) -> gymnasium.Env:
    return gymnasium.make(
        "contextrl/DmcWalker-v0", contexts=contexts, max_steps=max_steps, **VARIANTS[variant]
    )


def train(variant: str, timesteps: int, seed: int, max_steps: int = 1000) -> SAC:
    """SAC on a walker whose viscosity is resampled at every reset, hidden or visible."""
    model = SAC(
        "MlpPolicy",
        make_env(variant, TRAIN_CONTEXTS, max_steps),
        gamma=0.9,
        tau=0.001,
        batch_size=128,
        learning_rate=1e-3,
        buffer_size=100_000,
        ent_coef=0.2,
        learning_starts=min(5000, timesteps // 2),
        seed=seed,
        device="cpu",
    )
    return model.learn(total_timesteps=timesteps)


def test_viscosities(count: int, seed: int = 12345) -> np.ndarray:
    """Held-out test contexts from the training distribution (the same for every variant and seed)."""
    return np.random.default_rng(seed).uniform(LOW, HIGH, count)


def evaluate(model: SAC, variant: str, viscosities, max_steps: int = 1000) -> np.ndarray:
    """The greedy policy's return for one episode at each viscosity."""
    returns = []
    for index, viscosity in enumerate(viscosities):
        env = make_env(variant, {"viscosity": float(viscosity)}, max_steps)
        obs, _ = env.reset(seed=index)
        done, total = False, 0.0
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(action)
            total += reward
            done = terminated or truncated
        returns.append(total)
        env.close()
    return np.array(returns)


def main(argv=None) -> dict[str, np.ndarray]:
    """Test returns per variant, shaped (seeds, test contexts); prints their mean and spread."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timesteps", type=int, default=50_000, help="training steps per run")
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--test-contexts", type=int, default=20, help="the paper uses 200")
    parser.add_argument("--max-steps", type=int, default=1000, help="episode length (stock: 1000)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    viscosities = test_viscosities(args.test_contexts)
    results = {}
    for variant in VARIANTS:
        results[variant] = np.array(
            [
                evaluate(
                    train(variant, args.timesteps, seed, args.max_steps),
                    variant,
                    viscosities,
                    args.max_steps,
                )
                for seed in range(args.seeds)
            ]
        )
        per_seed = results[variant].mean(axis=1)
        print(
            f"{variant:>8}: test return {per_seed.mean():7.1f} "
            f"(seeds {', '.join(f'{r:.1f}' for r in per_seed)}) over {len(viscosities)} viscosities"
        )
    return results


if __name__ == "__main__":
    main()
