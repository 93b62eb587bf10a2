"""The agents beside the libraries a user would pick instead: final return at equal budgets, curves, time.

    python benchmarks/learning.py --purejaxrl FOLDER --cleanrl FOLDER [--seeds 5] [--only ROW ...]

Each row trains the same environment for the same number of environment steps with the same settings
(stated per row, with where they differ) in every library, ``--seeds`` seeds each, every library in a
process of its own: the project's agents and Stable-Baselines3 in the project's environment (SB3 is the
``sb3`` extra and trains on the project's gymnasium ids); PureJaxRL, CleanRL and brax's own PPO trainer
in virtual environments of their own (``.venv-purejaxrl``, ``.venv-cleanrl``, ``.venv-brax``), created
here on first use. PureJaxRL's and CleanRL's code is not on PyPI: ``--purejaxrl`` is a checkout of
luchris429/purejaxrl, whose ``ppo.py`` and ``ppo_continuous_action.py`` are imported unchanged and
their ``make_train`` called; ``--cleanrl`` a checkout of vwxyzjn/cleanrl, whose scripts run unchanged,
once per seed, as their command lines would. The final return is the
deterministic policy's mean over 10 episodes at the default context, one value per seed; the table
gives their IQM with a 95% interval over seeds (``contextrl.analysis``), the wall time of the whole run
with compilation, and steps per second (seeds × steps / wall time; the JAX agents of contextrl and
PureJaxRL train their seeds in one vmapped call, the others one after another). The curves are the
mean return of the training episodes that ended in each update or logging period, the median over
seeds with the band from the lowest to the highest seed.

Each row keeps its runs in ``benchmarks/results/learning_<row>.json`` (per library: each seed's final
return and curve, the date, the load average, the command), and writes its table beside it
(``learning_<row>.md``) and its curves to ``docs/images/learning_<row>.png``; the agents page shows
them. ``--libraries`` runs some of a row's libraries and keeps the others' runs (``--libraries
contextrl PureJaxRL --seeds 16 --suffix 16_seeds``: the JAX ones at more seeds, in files of their own);
``--redraw`` rewrites the tables and curves from the kept runs without running anything.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import pathlib
import shlex
import string
import subprocess
import sys
import tempfile
from collections.abc import Callable

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from _peers import ROOT  # noqa: E402

# Every library's XLA runs with the setting contextrl's runner applies (contextrl.xla_flags): without
# it, jaxlib 0.10's concurrency-optimised CPU scheduler can wedge a vmapped training program forever,
# every pool thread idle (PureJaxRL's five vmapped seeds did, here).
XLA_FLAGS = "--xla_cpu_enable_concurrency_optimized_scheduler=false"

# PureJaxRL's ppo.py defaults (its __main__ config): the settings of PPO on CartPole.
PPO_SETTINGS = {
    "learning_rate": 2.5e-4,
    "num_envs": 4,
    "num_steps": 128,
    "update_epochs": 4,
    "num_minibatches": 4,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_eps": 0.2,
    "ent_coef": 0.01,
    "vf_coef": 0.5,
    "max_grad_norm": 0.5,
    "anneal_lr": True,
}

# contextrl's run: the agent's seeds in one compiled call, then each seed's final return. $env is the
# environment, $agent the module, $config the lines that build ``config`` from steps and settings.
OURS = string.Template("""
import json, sys, time
import jax, numpy as np
from contextrl.xla_flags import xla_cpu_workaround
xla_cpu_workaround()
import contextrl as crl
from contextrl.agents import evaluate, $agent
steps, seeds, settings = int(sys.argv[1]), int(sys.argv[2]), json.loads(sys.argv[3])
env = crl.make($env)
context = env.default_context()
$config
start = time.perf_counter()
train = jax.jit(jax.vmap($agent.make_train(config, env, context)))
result = jax.block_until_ready(train(jax.random.split(jax.random.key(0), seeds)))
wall = time.perf_counter() - start
policy = $agent.make_policy(config, env, context)
final = jax.jit(jax.vmap(lambda params, key: evaluate(policy, params, env, context, 10, key)))(
    result.params, jax.random.split(jax.random.key(1), seeds))
curves = np.asarray(result.metrics["episode_return"], float)
print(json.dumps({"final": np.asarray(final).reshape(seeds).tolist(), "wall_s": wall,
                  "steps": np.asarray(result.metrics["step"])[0].tolist(),
                  "curves": np.where(np.isfinite(curves), curves, None).tolist()}))
""")

OURS_PPO = OURS.substitute(
    env='"CartPole"',
    agent="ppo",
    config="config = ppo.PPOConfig(total_timesteps=steps, hidden_sizes=(64, 64), activation='tanh', "
    "**settings)",
)

# PureJaxRL's own module $module, imported unchanged: its make_train with the row's settings in its
# config names, the seeds in one vmapped call after $setup; $episode defines ``episode(params, key)``, the
# deterministic policy's return until the first end (PureJaxRL's environments reset inside step;
# later rewards are ignored).
PUREJAXRL_RUN = string.Template("""
import json, sys, time
import jax, jax.numpy as jnp, numpy as np
folder, steps, seeds, settings = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), json.loads(sys.argv[4])
sys.path.insert(0, folder + "/purejaxrl")
import $module as purejaxrl
$setup
names = {"learning_rate": "LR", "num_envs": "NUM_ENVS", "num_steps": "NUM_STEPS",
         "update_epochs": "UPDATE_EPOCHS", "num_minibatches": "NUM_MINIBATCHES", "gamma": "GAMMA",
         "gae_lambda": "GAE_LAMBDA", "clip_eps": "CLIP_EPS", "ent_coef": "ENT_COEF",
         "vf_coef": "VF_COEF", "max_grad_norm": "MAX_GRAD_NORM", "anneal_lr": "ANNEAL_LR"}
config = {names[k]: v for k, v in settings.items()}
config.update({"TOTAL_TIMESTEPS": steps, "ACTIVATION": "tanh", "DEBUG": False, $config})
start = time.perf_counter()
train = jax.jit(jax.vmap(purejaxrl.make_train(config)))
out = jax.block_until_ready(train(jax.random.split(jax.random.PRNGKey(0), seeds)))
wall = time.perf_counter() - start
params = out["runner_state"][0].params
$episode

def final_return(params, key):
    return jax.vmap(lambda k: episode(params, k))(jax.random.split(key, 10)).mean()

final = jax.jit(jax.vmap(final_return))(params, jax.random.split(jax.random.PRNGKey(1), seeds))
metrics = out["metrics"]  # per seed, update, step and copy
ended = np.asarray(metrics["returned_episode"], bool)
returns = np.asarray(metrics["returned_episode_returns"], float)
count = ended.sum(axis=(2, 3))
curves = np.where(count > 0, (returns * ended).sum(axis=(2, 3)) / np.maximum(count, 1), np.nan)
batch = config["NUM_ENVS"] * config["NUM_STEPS"]
print(json.dumps({"final": np.asarray(final).reshape(seeds).tolist(), "wall_s": wall,
                  "steps": [batch * (i + 1) for i in range(curves.shape[1])],
                  "curves": np.where(np.isfinite(curves), curves, None).tolist()}))
""")

PUREJAXRL_PPO = PUREJAXRL_RUN.substitute(
    module="ppo",
    setup="",
    config='"ENV_NAME": "CartPole-v1"',
    episode="""import gymnax
env, env_params = gymnax.make("CartPole-v1")
network = purejaxrl.ActorCritic(env.action_space(env_params).n, activation="tanh")

def episode(params, key):
    reset_key, key = jax.random.split(key)
    obs, state = env.reset(reset_key, env_params)
    def step(carry, step_key):
        obs, state, total, alive = carry
        pi, _ = network.apply(params, obs)
        obs, state, reward, done, _ = env.step(step_key, state, jnp.argmax(pi.logits), env_params)
        return (obs, state, total + reward * alive, alive * (1.0 - done)), None
    carry = (obs, state, jnp.float32(0.0), jnp.float32(1.0))
    (_, _, total, _), _ = jax.lax.scan(step, carry, jax.random.split(key, env_params.max_steps_in_episode))
    return total""",
)

# PureJaxRL's ppo_continuous_action.py defaults (its __main__ config) for a cheap Brax task on a CPU:
# fewer copies and steps per update, the same learning rate, epochs, clipping, no entropy bonus, no
# learning-rate annealing; observations and rewards not normalised (contextrl's PPO has neither, so
# PureJaxRL's NORMALIZE_ENV and brax's normalize_observations are off).
BRAX_PPO_SETTINGS = {
    "learning_rate": 3e-4,
    "num_envs": 64,
    "num_steps": 32,
    "update_epochs": 4,
    "num_minibatches": 8,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_eps": 0.2,
    "ent_coef": 0.0,
    "vf_coef": 0.5,
    "max_grad_norm": 0.5,
    "anneal_lr": False,
}

# contextrl's PPO with PureJaxRL's continuous network (256×256, tanh) and the row's settings.
PPO_256 = "config = ppo.PPOConfig(total_timesteps=steps, hidden_sizes=(256, 256), activation='tanh', **settings)"

OURS_BRAX_PPO = OURS.substitute(
    env='"BraxInvertedDoublePendulum", backend="positional"', agent="ppo", config=PPO_256
)

# PureJaxRL's ppo_continuous_action.py on brax's inverted_double_pendulum (its BraxGymnaxWrapper:
# positional pipeline, 1,000-step episodes); the deterministic action is the mean, clipped to the
# action bounds as its ClipAction does.
PUREJAXRL_BRAX_PPO = PUREJAXRL_RUN.substitute(
    module="ppo_continuous_action",
    setup="",
    config='"ENV_NAME": "inverted_double_pendulum", "NORMALIZE_ENV": False',
    episode="""from wrappers import BraxGymnaxWrapper
env = BraxGymnaxWrapper("inverted_double_pendulum")
network = purejaxrl.ActorCritic(env.action_size, activation="tanh")

def episode(params, key):
    obs, state = env.reset(key)
    def step(carry, _):
        obs, state, total, alive = carry
        pi, _ = network.apply(params, obs)
        obs, state, reward, done, _ = env.step(None, state, jnp.clip(pi.mean(), -1.0, 1.0))
        return (obs, state, total + reward * alive, alive * (1.0 - done)), None
    carry = (obs, state, jnp.float32(0.0), jnp.float32(1.0))
    (_, _, total, _), _ = jax.lax.scan(step, carry, None, 1000)
    return total""",
)

# brax's own PPO trainer (brax.training.agents.ppo.train) on the same task and pipeline, in
# .venv-brax, one seed after another: its batches in its units
# (batch_size × num_minibatches unrolls of unroll_length steps = the copies × steps of an update),
# 256×256 tanh networks for policy and value; its curve is its evaluator's mean return over 10
# episodes at each of 10 evaluations (included in the wall time, a few seconds).
BRAX_TRAINER_PPO = """
import functools, json, sys, time
import jax, jax.numpy as jnp, numpy as np
from brax import envs
from brax.envs.wrappers.training import EpisodeWrapper
from brax.training.agents.ppo import networks, train as ppo
steps, seeds, settings = int(sys.argv[1]), int(sys.argv[2]), json.loads(sys.argv[3])
copies, minibatches = settings["num_envs"], settings["num_minibatches"]
factory = functools.partial(networks.make_ppo_networks, policy_hidden_layer_sizes=(256, 256),
                            value_hidden_layer_sizes=(256, 256), activation=jnp.tanh)
env = envs.get_environment("inverted_double_pendulum", backend="positional")
episode_env = EpisodeWrapper(env, episode_length=1000, action_repeat=1)
final, curves, wall = [], [], 0.0
for seed in range(seeds):
    points = []
    start = time.perf_counter()
    make_policy, params, _ = ppo.train(
        env, num_timesteps=steps, episode_length=1000, num_envs=copies,
        learning_rate=settings["learning_rate"], entropy_cost=settings["ent_coef"],
        discounting=settings["gamma"], gae_lambda=settings["gae_lambda"],
        unroll_length=settings["num_steps"], batch_size=copies // minibatches,
        num_minibatches=minibatches, num_updates_per_batch=settings["update_epochs"],
        clipping_epsilon=settings["clip_eps"], vf_loss_coefficient=settings["vf_coef"],
        max_grad_norm=settings["max_grad_norm"], normalize_observations=False,
        network_factory=factory, seed=seed, num_evals=11, num_eval_envs=10,
        progress_fn=lambda step, metrics: points.append((step, float(metrics["eval/episode_reward"]))))
    wall += time.perf_counter() - start
    policy = make_policy(params, deterministic=True)

    def episode(key):
        state = episode_env.reset(key)
        def step(carry, _):
            state, total, alive = carry
            action, _ = policy(state.obs, key)
            state = episode_env.step(state, action)
            return (state, total + state.reward * alive, alive * (1.0 - state.done)), None
        (_, total, _), _ = jax.lax.scan(step, (state, jnp.float32(0.0), jnp.float32(1.0)), None, 1000)
        return total

    returns = jax.jit(jax.vmap(episode))(jax.random.split(jax.random.PRNGKey(1000 + seed), 10))
    final.append(float(returns.mean()))
    curves.append([value for _, value in points[1:]])  # the evaluations after training began
print(json.dumps({"final": final, "wall_s": wall, "steps": [step for step, _ in points[1:]],
                  "curves": curves}))
"""


# A peer's final return: the deterministic policy ``act(observation) -> action`` over 10 episodes.
GREEDY = """def greedy_return(act, env_id, seed):
    env = gymnasium.make(env_id)
    discrete = not env.action_space.shape
    returns = []
    for episode in range(10):
        obs, _ = env.reset(seed=seed * 100 + episode)
        total, done = 0.0, False
        while not done:
            action = act(obs)
            obs, reward, terminated, truncated, _ = env.step(int(action) if discrete else action)
            total += reward
            done = terminated or truncated
        returns.append(total)
    return float(np.mean(returns))

def binned(ended, every, steps):
    # the mean return of the (step, return) episodes that ended in each period of ``every`` steps
    edges = list(range(every, steps + 1, every))
    means = []
    for edge in edges:
        inside = [r for step, r in ended if edge - every < step <= edge]
        means.append(float(np.mean(inside)) if inside else None)
    return edges, means
"""


# Stable-Baselines3's PPO on $env_id with $hidden tanh networks, one seed after another; the mean
# return of the training episodes that ended in each rollout makes the curve.
SB3_PPO_RUN = string.Template("""
ENV_ID = "$env_id"
import json, sys, time
import gymnasium, numpy as np, torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
import contextrl  # registers the contextrl ids
steps, seeds, settings = int(sys.argv[1]), int(sys.argv[2]), json.loads(sys.argv[3])
torch.set_num_threads(1)

class Episodes(BaseCallback):
    # the mean return of the training episodes that ended in each rollout
    def _on_rollout_end(self):
        ended = [info["r"] for info in self.model.ep_info_buffer][-self.new:] if self.new else []
        self.rows.append((self.num_timesteps, float(np.mean(ended)) if ended else None))
    def _on_rollout_start(self):
        self.new = 0
    def _on_step(self):
        self.new += int(np.sum(self.locals["dones"]))
        return True

$greedy
batch = settings["num_envs"] * settings["num_steps"]
start_lr = settings["learning_rate"]
schedule = (lambda remaining: remaining * start_lr) if settings["anneal_lr"] else start_lr
final, curves, wall = [], [], 0.0
for seed in range(seeds):
    start = time.perf_counter()
    envs = make_vec_env(ENV_ID, n_envs=settings["num_envs"], seed=seed)
    model = PPO("MlpPolicy", envs, n_steps=settings["num_steps"],
                batch_size=batch // settings["num_minibatches"], n_epochs=settings["update_epochs"],
                learning_rate=schedule, gamma=settings["gamma"], gae_lambda=settings["gae_lambda"],
                clip_range=settings["clip_eps"], ent_coef=settings["ent_coef"],
                vf_coef=settings["vf_coef"], max_grad_norm=settings["max_grad_norm"],
                policy_kwargs={"net_arch": $hidden, "activation_fn": torch.nn.Tanh},
                seed=seed, device="cpu")
    log = Episodes()
    log.rows = []
    model.learn(total_timesteps=steps, callback=log)
    wall += time.perf_counter() - start
    final.append(greedy_return(lambda obs: model.predict(obs, deterministic=True)[0], ENV_ID, seed))
    curves.append([value for _, value in log.rows])
    steps_axis = [step for step, _ in log.rows]
print(json.dumps({"final": final, "wall_s": wall, "steps": steps_axis, "curves": curves}))
""")

SB3_PPO = SB3_PPO_RUN.substitute(env_id="contextrl/CartPole-v0", hidden="[64, 64]", greedy=GREEDY)

# rl-baselines3-zoo's PPO settings for Pendulum-v1 (its ppo.yml) without its state-dependent
# exploration (an SB3-only feature) and with rollouts of 256 steps per copy instead of 1,024 (four
# times the updates): 4 copies, 10 epochs of minibatches of 64, learning rate 1e-3 (constant), γ 0.9,
# no entropy bonus.
PENDULUM_PPO_SETTINGS = {
    **PPO_SETTINGS,
    "learning_rate": 1e-3,
    "num_steps": 256,
    "update_epochs": 10,
    "num_minibatches": 16,
    "gamma": 0.9,
    "ent_coef": 0.0,
    "anneal_lr": False,
}

OURS_PENDULUM_PPO = OURS.substitute(env='"Pendulum"', agent="ppo", config=PPO_256)

# PureJaxRL's ppo_continuous_action.py builds its environment with BraxGymnaxWrapper(ENV_NAME); here
# that name is bound, before make_train runs, to gymnax's Pendulum-v1 in the same shape. The
# script's ClipAction clips actions to [-1, 1], so this stand-in scales them to the ±2 torque.
PUREJAXRL_PENDULUM_PPO = PUREJAXRL_RUN.substitute(
    module="ppo_continuous_action",
    setup="""import gymnax
from gymnax.environments import spaces

class GymnaxPendulum:
    def __init__(self, name, backend=None):
        self.env, self.params = gymnax.make(name)
    def reset(self, key, params=None):
        return self.env.reset(key, self.params)
    def step(self, key, state, action, params=None):
        return self.env.step(key, state, 2.0 * action, self.params)
    def observation_space(self, params):
        return self.env.observation_space(self.params)
    def action_space(self, params):
        return spaces.Box(-1.0, 1.0, (1,))

purejaxrl.BraxGymnaxWrapper = GymnaxPendulum""",
    config='"ENV_NAME": "Pendulum-v1", "NORMALIZE_ENV": False',
    episode="""pendulum = GymnaxPendulum("Pendulum-v1")
network = purejaxrl.ActorCritic(1, activation="tanh")

def episode(params, key):
    reset_key, key = jax.random.split(key)
    obs, state = pendulum.reset(reset_key)
    def step(carry, step_key):
        obs, state, total = carry
        pi, _ = network.apply(params, obs)
        obs, state, reward, _, _ = pendulum.step(step_key, state, jnp.clip(pi.mean(), -1.0, 1.0))
        return (obs, state, total + reward), None
    (_, _, total), _ = jax.lax.scan(step, (obs, state, jnp.float32(0.0)), jax.random.split(key, 200))
    return total""",
)

SB3_PENDULUM_PPO = SB3_PPO_RUN.substitute(
    env_id="contextrl/Pendulum-v0", hidden="[256, 256]", greedy=GREEDY
)


# Stable-Baselines3's SAC defaults where both libraries have the setting (one learning rate for actor,
# critics and temperature; an actor update every gradient step; the entropy target -dim(A)), with
# 1,000 warm-up steps and a 100,000-transition buffer.
SAC_SETTINGS = {
    "learning_rate": 3e-4,
    "buffer_size": 100_000,
    "learning_starts": 1_000,
    "batch_size": 256,
    "tau": 0.005,
    "gamma": 0.99,
    "log_every": 1_000,
    "torch_threads": 2,  # SB3's torch on both cores, as XLA runs
}

OURS_SAC = OURS.substitute(
    env='"Pendulum"',
    agent="sac",
    config="""rate = settings.pop("learning_rate")
settings.pop("torch_threads")
config = sac.SACConfig(total_timesteps=steps, num_envs=1, hidden_sizes=(256, 256), activation="relu",
                       policy_lr=rate, q_lr=rate, policy_frequency=1, autotune=True, **settings)""",
)


# CleanRL's settings for DQN on CartPole (its dqn_jax.py defaults), in its flags' names; contextrl's
# DQN and Stable-Baselines3's read the same values (the schedules converted to their units).
DQN_SETTINGS = {
    "learning_rate": 2.5e-4,
    "buffer_size": 10_000,
    "gamma": 0.99,
    "tau": 1.0,
    "target_network_frequency": 500,
    "batch_size": 128,
    "start_e": 1.0,
    "end_e": 0.05,
    "exploration_fraction": 0.5,
    "learning_starts": 10_000,
    "train_frequency": 10,
}

OURS_DQN = OURS.substitute(
    env='"CartPole"',
    agent="dqn",
    config="""# CleanRL's ε falls from start_e to end_e over exploration_fraction of the run counted from step 0;
# contextrl's starts after the warm-up (random actions), at the value CleanRL's has there.
decay, warm = settings["exploration_fraction"] * steps, settings["learning_starts"]
every = settings["train_frequency"]
config = dqn.DQNConfig(
    total_timesteps=steps, num_envs=1, hidden_sizes=(120, 84), n_step=1,
    learning_rate=settings["learning_rate"], buffer_size=settings["buffer_size"],
    gamma=settings["gamma"], tau=settings["tau"], batch_size=settings["batch_size"],
    target_update_interval=settings["target_network_frequency"] // every,
    start_epsilon=settings["start_e"] + (settings["end_e"] - settings["start_e"]) * min(warm / decay, 1),
    end_epsilon=settings["end_e"], exploration_fraction=(decay - warm) / (steps - warm),
    learning_starts=warm, train_frequency=every, max_grad_norm=1e9, log_every=steps // 50)""",
)

# CleanRL's c51_jax.py flags nearest the paper's C51 setting for CartPole (contextrl runs the paper's
# setting itself, dqn.paper_config): CleanRL has no n-step returns, Boltzmann exploration or soft
# target updates, so it keeps its ε schedule and copies the target every 1,000 steps (the time
# constant of τ = 0.001 per step).
C51_SETTINGS = {
    "learning_rate": 1e-3,
    "n_atoms": 51,
    "v_min": 0.0,
    "v_max": 110.0,
    "buffer_size": 100_000,
    "gamma": 0.99,
    "target_network_frequency": 1_000,
    "batch_size": 128,
    "learning_starts": 5_000,
    "train_frequency": 1,
}

OURS_C51 = OURS.substitute(
    env='"CartPole"',
    agent="dqn",
    config='config = dqn.paper_config("CartPole", total_timesteps=steps, log_every=steps // 50)',
)

# Stable-Baselines3's off-policy run on a contextrl gymnasium id: $algorithm built from the settings
# by $kwargs, one seed after another; each training episode's return with the step it ended at.
SB3_OFFPOLICY = string.Template("""
ENV_ID = "$env_id"
import json, sys, time
import gymnasium, numpy as np, torch
from stable_baselines3 import $algorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor
import contextrl  # registers the contextrl ids
steps, seeds, settings = int(sys.argv[1]), int(sys.argv[2]), json.loads(sys.argv[3])
$kwargs

class Episodes(BaseCallback):
    def _on_step(self):
        for info in self.locals["infos"]:
            if "episode" in info:
                self.ended.append((self.num_timesteps, info["episode"]["r"]))
        return True

$greedy
final, curves, wall = [], [], 0.0
for seed in range(seeds):
    start = time.perf_counter()
    model = $algorithm("MlpPolicy", Monitor(gymnasium.make(ENV_ID)), seed=seed, device="cpu", **kwargs)
    log = Episodes()
    log.ended = []
    model.learn(total_timesteps=steps, callback=log)
    wall += time.perf_counter() - start
    final.append(greedy_return(lambda obs: model.predict(obs, deterministic=True)[0], ENV_ID, seed))
    edges, curve = binned(log.ended, every, steps)
    curves.append(curve)
print(json.dumps({"final": final, "wall_s": wall, "steps": edges, "curves": curves}))
""")

SB3_DQN = SB3_OFFPOLICY.substitute(
    env_id="contextrl/CartPole-v0",
    algorithm="DQN",
    greedy=GREEDY,
    kwargs="""torch.set_num_threads(1)
every = max(1, steps // 50)
kwargs = dict(
    learning_rate=settings["learning_rate"], buffer_size=settings["buffer_size"],
    learning_starts=settings["learning_starts"], batch_size=settings["batch_size"],
    tau=settings["tau"], gamma=settings["gamma"], train_freq=settings["train_frequency"],
    gradient_steps=1, target_update_interval=settings["target_network_frequency"],
    exploration_fraction=settings["exploration_fraction"], exploration_initial_eps=settings["start_e"],
    exploration_final_eps=settings["end_e"], max_grad_norm=1e9,
    policy_kwargs={"net_arch": [120, 84]})""",
)

# Stable-Baselines3's DQN with the settings rl-baselines3-zoo tuned for CartPole-v1 (its dqn.yml):
# the same harness with a setting known to learn there.
SB3_DQN_ZOO = SB3_OFFPOLICY.substitute(
    env_id="contextrl/CartPole-v0",
    algorithm="DQN",
    greedy=GREEDY,
    kwargs="""torch.set_num_threads(1)
every = max(1, steps // 50)
kwargs = dict(
    learning_rate=2.3e-3, batch_size=64, buffer_size=100_000, learning_starts=1_000, gamma=0.99,
    target_update_interval=10, train_freq=256, gradient_steps=128, exploration_fraction=0.16,
    exploration_final_eps=0.04, policy_kwargs={"net_arch": [256, 256]})""",
)

SB3_SAC_KWARGS = """torch.set_num_threads(int(settings.pop("torch_threads")))
every = settings.pop("log_every")
kwargs = dict(policy_kwargs={"net_arch": [256, 256]}, **settings)"""

SB3_SAC = SB3_OFFPOLICY.substitute(
    env_id="contextrl/Pendulum-v0", algorithm="SAC", greedy=GREEDY, kwargs=SB3_SAC_KWARGS
)

# CleanRL's own script (FOLDER/cleanrl/$script.py, unchanged) run once per seed as its command line
# would, with the settings as its flags; its printed episode returns make the curve, and $act, over
# the script's variables after the run, the deterministic action.
CLEANRL = string.Template("""
import contextlib, io, json, re, runpy, sys, time
import gymnasium, numpy as np
folder, steps, seeds, settings = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), json.loads(sys.argv[4])
sys.path.insert(0, folder)  # its cleanrl_utils
ENV_ID = "$env_id"
$greedy
every = int(settings.pop("log_every", max(1, steps // 50)))
flags = [f"--{'' if value else 'no-'}{name}" if isinstance(value, bool) else f"--{name}={value}"
         for name, value in ((k.replace("_", "-"), v) for k, v in settings.items())]
final, curves, wall = [], [], 0.0
for seed in range(seeds):
    sys.argv = ["$script.py", f"--seed={seed}", f"--env-id={ENV_ID}", f"--total-timesteps={steps}", *flags]
    printed = io.StringIO()
    start = time.perf_counter()
    with contextlib.redirect_stdout(printed):
        run = runpy.run_path(f"{folder}/cleanrl/$script.py", run_name="__main__")
    wall += time.perf_counter() - start
    $act
    final.append(greedy_return(act, ENV_ID, seed))
    pattern = r"global_step=(\\d+), episodic_return=\\[?([-0-9.e+]+)"
    ended = [(int(step) + 1, float(value)) for step, value in re.findall(pattern, printed.getvalue())]
    edges, curve = binned(ended, every, steps)
    curves.append(curve)
print(json.dumps({"final": final, "wall_s": wall, "steps": edges, "curves": curves}))
""")

CLEANRL_DQN = CLEANRL.substitute(
    env_id="CartPole-v1",
    script="dqn_jax",
    greedy=GREEDY,
    act='act = lambda obs: int(run["q_network"].apply(run["q_state"].params, obs[None]).argmax())',
)

CLEANRL_C51 = CLEANRL.substitute(
    env_id="CartPole-v1",
    script="c51_jax",
    greedy=GREEDY,
    act="""q_state, network = run["q_state"], run["q_network"]
    act = lambda obs: int((network.apply(q_state.params, obs[None]) * q_state.atoms).sum(-1).argmax())""",
)

# CleanRL's SAC actor: the third output of get_action is the squashed mean.
CLEANRL_SAC_ACT = """import torch
    actor = run["actor"]
    act = lambda obs: actor.get_action(torch.as_tensor(obs[None], dtype=torch.float32))[2][0].detach().numpy()"""

CLEANRL_SAC = CLEANRL.substitute(
    env_id="Pendulum-v1", script="sac_continuous_action", greedy=GREEDY, act=CLEANRL_SAC_ACT
)


# SAC on DmcWalker: the Pendulum row's settings with 5,000 warm-up steps (the paper's), on dm_control's
# walker-walk, whose 1,000-step episodes make a slower and longer task.
DMC_SAC_SETTINGS = {**SAC_SETTINGS, "learning_starts": 5_000}

# contextrl's SAC on a host environment: the shared host loop (sac.train_gymnasium), one seed after
# another; the deterministic policy acts through the environment's gymnasium id.
OURS_HOST_SAC = string.Template("""
ENV_ID = "contextrl/$env-v0"
import json, sys, time
import gymnasium, jax, numpy as np
from contextrl.xla_flags import xla_cpu_workaround
xla_cpu_workaround()
import contextrl as crl
from contextrl.agents import sac
steps, seeds, settings = int(sys.argv[1]), int(sys.argv[2]), json.loads(sys.argv[3])
rate = settings.pop("learning_rate")
settings.pop("torch_threads")
config = sac.SACConfig(total_timesteps=steps, num_envs=1, hidden_sizes=(256, 256), activation="relu",
                       policy_lr=rate, q_lr=rate, policy_frequency=1, autotune=True, **settings)
env = crl.make("$env")
context = env.default_context()
contexts = env.context_space.stack([context])
policy = sac.make_policy(config, env, contexts)
$greedy
final, curves, wall = [], [], 0.0
for seed in range(seeds):
    start = time.perf_counter()
    result = sac.train_gymnasium(config, "$env", contexts, jax.random.key(seed), seed=seed)
    wall += time.perf_counter() - start
    act = jax.jit(lambda obs: policy(result.params, obs, context, jax.random.key(0)))
    final.append(greedy_return(lambda obs: np.asarray(act(obs)), ENV_ID, seed))
    curve = np.asarray(result.metrics["episode_return"], float)
    curves.append(np.where(np.isfinite(curve), curve, None).tolist())
print(json.dumps({"final": final, "wall_s": wall,
                  "steps": np.asarray(result.metrics["step"]).tolist(), "curves": curves}))
""")

OURS_DMC_SAC = OURS_HOST_SAC.substitute(env="DmcWalker", greedy=GREEDY)

SB3_DMC_SAC = SB3_OFFPOLICY.substitute(
    env_id="contextrl/DmcWalker-v0",
    algorithm="SAC",
    greedy=GREEDY,
    kwargs=SB3_SAC_KWARGS,
)

# CleanRL's SAC on dm_control's walker-walk through shimmy (gymnasium 0.29's dm_control ids), its
# observation dictionary flattened: registered under an id of its own before the script runs.
CLEANRL_DMC_SAC = CLEANRL.substitute(
    env_id="DmcWalkerFlat-v0",
    script="sac_continuous_action",
    greedy=GREEDY
    + """
gymnasium.register("DmcWalkerFlat-v0", entry_point=lambda **options: gymnasium.wrappers.FlattenObservation(
    gymnasium.make("dm_control/walker-walk-v0", **options)))
""",
    act=CLEANRL_SAC_ACT,
)


def cleanrl_sac_settings(settings: dict) -> dict:
    """The SAC row's settings in CleanRL's flags: one learning rate for actor, critics and the
    temperature, an actor update every step, the target every step, on the CPU."""
    return {
        "policy_lr": settings["learning_rate"],
        "q_lr": settings["learning_rate"],
        "policy_frequency": 1,
        "target_network_frequency": 1,
        "autotune": True,
        "cuda": False,
        **{
            k: settings[k] for k in ("buffer_size", "learning_starts", "batch_size", "tau", "gamma")
        },
        "log_every": settings["log_every"],
    }


@dataclasses.dataclass(frozen=True)
class Peer:
    """A peer library: its virtual environment beside the checkout, created on first use (pip
    ``groups`` in order, at the project's pins where ``pinned``), and the code of a checkout of it."""

    name: str
    venv: str
    groups: tuple[tuple[str, ...], ...]
    probe: str
    marker: str | None  # a file every checkout of its code has (None: its code is on PyPI)
    pinned: bool

    def python(self) -> pathlib.Path:
        python = ROOT / self.venv / "bin" / "python"
        probe = [str(python), "-c", self.probe]
        if python.exists() and subprocess.run(probe, capture_output=True).returncode == 0:
            return python
        print(f"preparing {self.venv} (once)...", file=sys.stderr)
        if not python.exists():
            subprocess.run([sys.executable, "-m", "venv", str(ROOT / self.venv)], check=True)
        pins = ["-c", str(ROOT / "constraints.txt")] if self.pinned else []
        for group in self.groups:
            subprocess.run([str(python), "-m", "pip", "install", "-q", *pins, *group], check=True)
        subprocess.run(probe, check=True)
        return python


# PureJaxRL's own requirements (its requirements.txt; navix imports wandb) at the project's pins
# (constraints.txt: JAX, flax, optax, gymnax, brax). distrax goes in without its dependencies and
# on tensorflow-probability's nightly: the release fails under this JAX (tools/run_purejaxrl.py).
PUREJAXRL = Peer(
    "PureJaxRL",
    ".venv-purejaxrl",
    (
        ("jax", "jaxlib", "flax", "optax", "gymnax", "brax", "navix", "wandb", "chex", "dm-tree"),
        ("--no-deps", "distrax", "tfp-nightly", "decorator", "cloudpickle", "gast"),
    ),
    "import distrax, gymnax, brax, navix, flax, optax",
    "purejaxrl/ppo.py",
    pinned=True,
)

# CleanRL's scripts use gymnasium 0.29's vector API (final_info, final_observation) at CleanRL's pin,
# 0.29.1, which needs numpy < 2: JAX is then the newest release for numpy 1.x (CleanRL's own pin,
# jaxlib 0.4.7, has no wheel for this Python). torch, the CPU build, runs its replay buffer, its
# tensorboard writer and the SAC networks; shimmy 1.3 (the last for gymnasium 0.29) gives dm_control
# at the project's pin a gymnasium 0.29 id.
CLEANRL = Peer(
    "CleanRL",
    ".venv-cleanrl",
    (
        (
            "jax==0.7.1",
            "jaxlib==0.7.1",
            "flax==0.12.0",
            "optax==0.2.8",
            "numpy==1.26.4",
            "gymnasium==0.29.1",
            "tyro==0.5.10",
            "tensorboard==2.21.0",
            "torch==2.13.0",
            "dm_control==1.0.50",
            "mujoco==3.17.0",
            "shimmy==1.3.0",
            "imageio==2.28.1",  # gymnasium's MuJoCo renderer, which shimmy imports
        ),
    ),
    "import jax, flax, optax, gymnasium, tyro, torch, tensorboard, shimmy, dm_control",
    "cleanrl/dqn_jax.py",
    pinned=False,
)
# brax's own PPO trainer: brax 0.14.2 (the project's pin) calls jax.device_put_replicated, which the
# project's JAX no longer has, so it runs on the newest JAX that still does.
BRAX = Peer(
    "brax",
    ".venv-brax",
    (("brax==0.14.2", "mujoco-mjx==3.17.0", "mujoco==3.17.0", "jax==0.8.2", "jaxlib==0.8.2"),),
    "from brax.training.agents.ppo import train",
    None,
    pinned=False,
)
PEERS = (PUREJAXRL, CLEANRL)  # the peers whose code comes from a checkout


@dataclasses.dataclass(frozen=True)
class Library:
    """One library's run of a row: a script that takes steps, seeds and the settings as JSON (after
    the peer's checkout, for a peer's code) and prints one JSON line: each seed's final return, the
    wall time, and the training curves."""

    name: str
    script: str
    peer: Peer | None = None  # None: the project's environment
    adapt: Callable[[dict], dict] | None = None  # the row's settings in this library's names


@dataclasses.dataclass(frozen=True)
class Row:
    title: str
    steps: int
    settings: dict
    libraries: tuple[Library, ...]
    note: str


ROWS = {
    "ppo_cartpole": Row(
        "PPO, CartPole",
        200_000,
        PPO_SETTINGS,
        (
            Library("contextrl", OURS_PPO),
            Library("PureJaxRL", PUREJAXRL_PPO, PUREJAXRL),
            Library("Stable-Baselines3", SB3_PPO),
        ),
        "PureJaxRL's ppo.py settings in every library: 4 copies × 128 steps, 4 epochs of 4 "
        "minibatches, learning rate 2.5e-4 annealed to 0, entropy 0.01, 64×64 tanh networks; "
        "gymnax's CartPole-v1 for PureJaxRL, contextrl/CartPole-v0 at the default context (the "
        "same dynamics, 500 steps) for the others; SB3's torch on one thread",
    ),
    "ppo_pendulum": Row(
        "PPO, Pendulum",
        200_000,
        PENDULUM_PPO_SETTINGS,
        (
            Library("contextrl", OURS_PENDULUM_PPO),
            Library("PureJaxRL", PUREJAXRL_PENDULUM_PPO, PUREJAXRL),
            Library("Stable-Baselines3", SB3_PENDULUM_PPO),
            Library(
                "contextrl, value change not clipped",
                OURS_PENDULUM_PPO,
                adapt=lambda settings: {**settings, "clip_value": False},
            ),
        ),
        "rl-baselines3-zoo's Pendulum-v1 settings without its state-dependent exploration and "
        "with rollouts of 256 steps per copy instead of 1,024, in every library: 4 copies, 10 "
        "epochs of minibatches of 64, learning rate 1e-3 "
        "(constant), γ 0.9, λ 0.95, clip 0.2, no entropy bonus, 256×256 tanh networks (PureJaxRL's "
        "ppo_continuous_action.py fixes that size), a Gaussian with a state-independent deviation; "
        "contextrl/Pendulum-v0 at the default context for contextrl and SB3, gymnax's Pendulum-v1 "
        "for PureJaxRL, whose script runs Brax tasks only and gets gymnax's in their place, its "
        "actions in [-1, 1] scaled to the ±2 torque (so its initial deviation is 2 in torque, 1 in "
        "the others); the end of an episode at 200 steps bootstraps in contextrl and SB3, ends the "
        "return in PureJaxRL; SB3 does not clip the value change (the last line: contextrl with "
        "clip_value=False); SB3's torch on one thread",
    ),
    "dqn_cartpole": Row(
        "DQN, CartPole",
        100_000,
        DQN_SETTINGS,
        (
            Library("contextrl", OURS_DQN),
            Library("CleanRL", CLEANRL_DQN, CLEANRL),
            Library("Stable-Baselines3", SB3_DQN),
            Library("Stable-Baselines3, rl-zoo's settings", SB3_DQN_ZOO),
        ),
        "CleanRL's dqn_jax.py settings in every library: one copy, 120×84 ReLU network, learning "
        "rate 2.5e-4, batch 128, a gradient step every 10 steps after 10,000 warm-up steps, the "
        "target copied every 500 steps, a 10,000-step buffer, ε from 1 to 0.05 over the first half, "
        "one-step targets, no gradient clipping; the squared TD error in contextrl and CleanRL, "
        "SB3's Huber loss (its DQN has no other); gymnasium 0.29's CartPole-v1 for CleanRL, "
        "contextrl/CartPole-v0 at the default context for the others; SB3's torch on one thread. "
        "The last line is SB3's DQN with rl-baselines3-zoo's CartPole-v1 settings instead (learning "
        "rate 2.3e-3, batch 64, 128 gradient steps every 256 steps, the target every 10 steps, "
        "1,000 warm-up steps, ε to 0.04 over 16%, 256×256)",
    ),
    "c51_cartpole": Row(
        "C51, CartPole",
        100_000,
        C51_SETTINGS,
        (Library("contextrl", OURS_C51), Library("CleanRL", CLEANRL_C51, CLEANRL)),
        "The paper's C51 setting for CartPole (appendix table) in contextrl: 5-step returns, "
        "Boltzmann exploration at temperature 0.1, soft target updates τ = 0.001, 256×256 network, "
        "learning rate 1e-3, batch 128, 5,000 warm-up steps, a 100,000-step buffer, 51 atoms on "
        "[0, 110]; CleanRL's c51_jax.py with the same learning rate, batch, warm-up, buffer and "
        "atoms, a gradient step every step, and what its script fixes: one-step returns, ε from 1 "
        "to 0.05 over the first half, the target copied every 1,000 steps, a 120×84 network",
    ),
    "sac_pendulum": Row(
        "SAC, Pendulum",
        10_000,
        SAC_SETTINGS,
        (
            Library("contextrl", OURS_SAC),
            Library("Stable-Baselines3", SB3_SAC),
            Library("CleanRL", CLEANRL_SAC, CLEANRL, cleanrl_sac_settings),
        ),
        "Stable-Baselines3's SAC settings in every library: one learning rate 3e-4 for actor, "
        "critics and the temperature (tuned towards entropy -1), an actor update every step, batch "
        "256, τ 0.005, γ 0.99, 256×256 ReLU networks, one copy; 1,000 warm-up steps, a "
        "100,000-step buffer; contextrl/Pendulum-v0 at the default context (200-step episodes), "
        "gymnasium 0.29's Pendulum-v1 for CleanRL; torch on both cores",
    ),
    "ppo_brax": Row(
        "PPO, Brax InvertedDoublePendulum",
        1_000_000,
        BRAX_PPO_SETTINGS,
        (
            Library("contextrl", OURS_BRAX_PPO),
            Library("PureJaxRL", PUREJAXRL_BRAX_PPO, PUREJAXRL),
            Library("brax", BRAX_TRAINER_PPO, BRAX),
        ),
        "PureJaxRL's ppo_continuous_action.py settings with 64 copies × 32 steps per update: "
        "4 epochs of 8 minibatches, learning rate 3e-4 (constant), no entropy bonus, clip 0.2, "
        "256×256 tanh networks, observations and rewards not normalised; brax's "
        "inverted_double_pendulum on its positional pipeline, 1,000-step episodes, in every "
        "library (contextrl's BraxInvertedDoublePendulum at the default context, backend "
        "positional). PureJaxRL's and contextrl's policies are a Gaussian with a learned "
        "state-independent deviation, actions clipped; brax's a tanh-squashed Gaussian with a "
        "state-dependent deviation (its only policy)",
    ),
    "sac_dmcwalker": Row(
        "SAC, DmcWalker",
        20_000,
        DMC_SAC_SETTINGS,
        (
            Library("contextrl", OURS_DMC_SAC),
            Library("Stable-Baselines3", SB3_DMC_SAC),
            Library("CleanRL", CLEANRL_DMC_SAC, CLEANRL, cleanrl_sac_settings),
        ),
        "The SAC Pendulum row's settings with 5,000 warm-up steps; dm_control's walker-walk "
        "(1,000-step episodes): contextrl/DmcWalker-v0 at the default context for contextrl "
        "(through its host loop) and SB3, shimmy's dm_control/walker-walk-v0 with its observation "
        "flattened for CleanRL; torch on both cores",
    ),
}


def run_library(library: Library, row: Row, seeds: int, checkouts: dict) -> dict:
    """One library's seeds of a row, in a process of its own (and a scratch folder: CleanRL writes
    its logs where it runs)."""
    settings = library.adapt(row.settings) if library.adapt else row.settings
    arguments = [str(row.steps), str(seeds), json.dumps(settings)]
    python = pathlib.Path(sys.executable)
    if library.peer:
        python = library.peer.python()
    if library.peer and library.peer.marker:
        arguments.insert(0, str(checkouts[library.peer.name]))
    with tempfile.TemporaryDirectory() as scratch:
        result = subprocess.run(
            [str(python), "-c", library.script, *arguments],
            capture_output=True,
            text=True,
            env={**os.environ, "PYTHONWARNINGS": "ignore", "XLA_FLAGS": XLA_FLAGS},
            cwd=scratch,
        )
    if result.returncode:
        raise RuntimeError(f"{library.name}: {result.stderr.strip()[-2000:]}")
    return json.loads(result.stdout.strip().splitlines()[-1])


def summary(final: list[float], seed: int) -> str:
    """IQM of the per-seed final returns with its 95% interval over seeds."""
    from contextrl.analysis import SEEDS, aggregate_iqm, bootstrap_ci

    interval = bootstrap_ci(np.asarray(final, float)[:, None], aggregate_iqm, unit=SEEDS, seed=seed)
    return str(interval)


def smoothed(curves: np.ndarray) -> np.ndarray:
    """Each seed's curve averaged over a window of about 1/20 of training (an update's mean return
    is noisy), skipping updates in which no episode ended."""
    import pandas as pd

    window = max(1, curves.shape[1] // 20)
    return pd.DataFrame(curves.T).rolling(window, min_periods=1).mean().to_numpy().T


def draw(path: pathlib.Path, row: Row, runs: dict[str, dict]) -> pathlib.Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter

    figure = Figure(figsize=(5.5, 3.4), layout="constrained")
    axes = figure.add_subplot()
    for library, run in runs.items():
        steps = np.asarray(run["steps"], float)
        curves = smoothed(np.asarray(run["curves"], float))  # None became NaN: nothing ended
        axes.fill_between(steps, np.nanmin(curves, 0), np.nanmax(curves, 0), alpha=0.2, lw=0)
        axes.plot(steps, np.nanmedian(curves, 0), lw=1.5, label=f"{library} ({run['seeds']} seeds)")
    axes.set_title(f"{row.title}: training return", fontsize=10)
    axes.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:g}k"))
    axes.set_xlabel("environment steps")
    axes.set_ylabel("episode return")
    axes.grid(alpha=0.3)
    axes.legend(fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(figure).print_png(str(path))
    return path


def table(row: Row, runs: dict[str, dict]) -> str:
    """The row's Markdown: its settings, one line per library, and when and how each was measured."""
    ours = runs.get("contextrl", {}).get("wall_s")
    lines = [
        f"**{row.title}, {row.steps:,} steps.** {row.note}.",
        "",
        "| library | seeds | final return, IQM (95% CI over seeds) | per seed | wall time | steps/s "
        "| its time / contextrl's |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for library, run in runs.items():
        rate = run["seeds"] * row.steps / run["wall_s"]
        per_seed = ", ".join(f"{v:.0f}" for v in run["final"])
        ratio = f"{run['wall_s'] / ours:.2f}" if ours else "–"
        lines.append(
            f"| {library} | {run['seeds']} | {summary(run['final'], 0)} | {per_seed} | "
            f"{run['wall_s']:.0f} s | {rate:,.0f} | {ratio} |"
        )
    measured = {}  # libraries run together share a date and a load
    for library, run in runs.items():
        key = f"on {run['date']}, load {run['load'][0]:.1f} → {run['load'][1]:.1f}"
        measured.setdefault(key, []).append(library)
    when = "; ".join(f"{', '.join(names)} {key}" for key, names in measured.items())
    commands = ", ".join(dict.fromkeys(f"`{run['command']}`" for run in runs.values()))
    cpu = next(iter(runs.values()))["cpu"]
    return "\n".join([*lines, "", f"Measured on {cpu} ({when}) with {commands}.", ""])


def cpu_name() -> str:
    models = [
        line.split(":", 1)[1].strip()
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines()
        if line.startswith("model name")
    ]
    return f"{models[0] if models else 'CPU'}, {os.cpu_count()} core(s)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--only", nargs="+", choices=list(ROWS), default=list(ROWS))
    parser.add_argument("--libraries", nargs="+", help="only these libraries (default: every one)")
    for peer in PEERS:
        parser.add_argument(
            f"--{peer.name.lower()}", type=pathlib.Path, help=f"a checkout of {peer.name}"
        )
    parser.add_argument("--suffix", default="", help="name the row's files learning_<row>_<suffix>")
    parser.add_argument(
        "--redraw", action="store_true", help="rewrite tables and curves, run nothing"
    )
    args = parser.parse_args()
    chosen = {
        name: [lib for lib in ROWS[name].libraries if lib.name in (args.libraries or [lib.name])]
        for name in args.only
    }
    checkouts = {peer.name: getattr(args, peer.name.lower()) for peer in PEERS}
    peers = {lib.peer for libs in chosen.values() for lib in libs if lib.peer and lib.peer.marker}
    for peer in [] if args.redraw else peers:
        checkout = checkouts[peer.name]
        if not (checkout and (checkout / peer.marker).is_file()):
            parser.error(f"--{peer.name.lower()}: give a checkout of {peer.name} ({peer.marker})")
    command = shlex.join(["python", "benchmarks/learning.py", *sys.argv[1:]])
    results = ROOT / "benchmarks" / "results"
    for name, libraries in chosen.items():
        row = ROWS[name]
        stem = f"learning_{name}" + (f"_{args.suffix}" if args.suffix else "")
        raw = results / f"{stem}.json"
        kept = json.loads(raw.read_text()) if raw.exists() else {}
        if args.redraw and not kept.get("runs"):
            continue
        if kept.get("steps") != row.steps:
            kept = {
                "steps": row.steps,
                "runs": {},
            }  # another budget: the runs kept are not comparable
        for library in [] if args.redraw else libraries:
            load = os.getloadavg()[0]
            run = run_library(library, row, args.seeds, checkouts)
            run.update(
                seeds=args.seeds,
                date=datetime.date.today().isoformat(),
                load=[load, os.getloadavg()[0]],
                command=command,
                cpu=cpu_name(),
            )
            kept["runs"][library.name] = run
            print(
                f"{row.title}, {library.name}: final {np.round(run['final'], 1).tolist()}",
                flush=True,
            )
            raw.write_text(json.dumps(kept) + "\n")  # each library as it finishes
        order = [lib.name for lib in row.libraries]
        runs = dict(sorted(kept["runs"].items(), key=lambda item: order.index(item[0])))
        text = table(row, runs)
        (results / f"{stem}.md").write_text(text)
        image = draw(ROOT / "docs" / "images" / f"{stem}.png", row, runs)
        print(text)
        print(f"wrote {raw}, {results / f'{stem}.md'} and {image}")


if __name__ == "__main__":
    main()
