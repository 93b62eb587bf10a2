"""The learning tests' runs as functions of their seeds, shared by the tests and the margin script.

A learning test asserts a statistic of a few seeds. Whether that statistic can fail by luck is a
question about its distribution, which ``tests/helpers/margins.py`` measures by running the same
function here over many seeds and under two numerics; each test's docstring quotes what it printed.
Every function returns per-seed numbers (numpy arrays, one entry per seed), never a verdict.
"""

from __future__ import annotations

import importlib.util
import sys

import jax
import jax.numpy as jnp
import numpy as np

import contextrl as crl
from contextrl.agents import dqn, evaluate, get_agent, ppo, sac
from tests.helpers import ROOT

EXAMPLES = ROOT / "examples"

# XLA's default code generation, whatever XLA_FLAGS says (the suite turns the fusion emitters off to
# compile faster, conftest.py): a learning test runs the numerics its margins were measured on. A
# program compiled with these options is bit for bit the one compiled without any XLA flag.
MEASURED_NUMERICS = {"xla_backend_optimization_level": 3, "xla_cpu_use_fusion_emitters": True}


# UR5e's six-link chain steps up to 50 × slower with the fusion emitters (docs/benchmarks.md, docs/
# troubleshooting.md), so its learning test pins the older emitters, at LLVM's default optimisation.
OLDER_EMITTERS = {**MEASURED_NUMERICS, "xla_cpu_use_fusion_emitters": False}


def measured_jit(function, numerics=MEASURED_NUMERICS):
    """``jax.jit`` under the numerics the margins were measured on, whatever the suite's flags."""
    return jax.jit(function, compiler_options=numerics)


def _keys(seeds, offset: int = 0):
    return jax.vmap(jax.random.key)(jnp.asarray(seeds, jnp.uint32) + offset)


def _train_and_evaluate(module, config, env, train_contexts, eval_context, seeds, episodes=10):
    """Train one agent per seed in one vmapped call; each seed's mean evaluation return and curve."""
    train = module.make_train(config, env, train_contexts)
    result = measured_jit(jax.vmap(train))(_keys(seeds))
    policy = module.make_policy(config, env, train_contexts)
    returns = measured_jit(
        jax.vmap(lambda params, key: evaluate(policy, params, env, eval_context, episodes, key))
    )(result.params, _keys(seeds, 10_000))
    return np.asarray(returns).reshape(len(seeds)), result


def ppo_cartpole(seeds) -> dict[str, np.ndarray]:
    """PPO, 100k steps (8 copies × 128 steps, lr 2.5e-3) at CartPole's default context."""
    env = crl.make("CartPole")
    config = ppo.PPOConfig(total_timesteps=100_000, num_envs=8, learning_rate=2.5e-3)
    context = env.default_context()
    final, result = _train_and_evaluate(ppo, config, env, context, context, seeds)
    curve = np.asarray(result.metrics["episode_return"])
    return {"return": final, "first_updates": np.nanmean(curve[:, :5], axis=1)}


DQN_LEARNING = dict(
    total_timesteps=48_000,
    num_envs=4,
    hidden_sizes=(64, 64),
    learning_starts=2000,
    target_update_interval=100,
)


def _dqn_cartpole(seeds, **options) -> dict[str, np.ndarray]:
    env = crl.make("CartPole")
    config = dqn.DQNConfig(**DQN_LEARNING, **options)
    context = env.default_context()
    final, result = _train_and_evaluate(dqn, config, env, context, context, seeds)
    curve = np.asarray(result.metrics["episode_return"])
    return {"return": final, "first_rows": np.nanmean(curve[:, :2], axis=1)}


def dqn_cartpole(seeds) -> dict[str, np.ndarray]:
    """DQN, 48k steps (4 copies, 11.5k gradient steps, 64×64 MLP) at CartPole's default context."""
    return _dqn_cartpole(seeds)


def c51_cartpole(seeds) -> dict[str, np.ndarray]:
    """C51 (51 atoms on [0, 110], as in the paper), otherwise as :func:`dqn_cartpole`."""
    return _dqn_cartpole(seeds, distributional=True, v_min=0.0, v_max=110.0)


def sac_pendulum(seeds) -> dict[str, np.ndarray]:
    """SAC, 16k steps (2 copies, 1k warm-up transitions, 64×64 MLPs) at Pendulum's default context."""
    env = crl.make("Pendulum")
    config = sac.SACConfig(
        total_timesteps=16_000,
        num_envs=2,
        hidden_sizes=(64, 64),
        learning_starts=1000,
        policy_frequency=1,
    )
    context = env.default_context()
    final, result = _train_and_evaluate(sac, config, env, context, context, seeds)
    curve = np.asarray(result.metrics["episode_return"])
    return {
        "return": final,
        "first_rows": np.nanmean(curve[:, :2], axis=1),
        "final_alpha": np.asarray(result.metrics["alpha"])[:, -1],
    }


def load_example(name: str):
    """examples/NAME.py as a module, as a user would run it."""
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def purejaxrl_cartpole(seeds) -> dict[str, np.ndarray]:
    """examples/purejaxrl_ppo_cartpole.py (PureJaxRL's PPO on the gymnax face, 100k steps, pole
    lengths resampled from U(0.25, 0.75)): mean return of the first 5 and the last 10 % of updates."""
    example = load_example("purejaxrl_ppo_cartpole")
    out = measured_jit(jax.vmap(example.make_train(example.CONFIG)))(_keys(seeds))
    returns = np.asarray(jax.vmap(example.returns_per_update)(out["metrics"]))
    tail = returns.shape[1] // 10
    return {
        "first_updates": np.nanmean(returns[:, :5], axis=1),
        "last_updates": np.nanmean(returns[:, -tail:], axis=1),
    }


def sb3_cartpole(seeds, timesteps: int = 60_000) -> dict[str, np.ndarray]:
    """examples/sb3_ppo_cartpole.py as users run it (Stable-Baselines3 PPO, pole lengths resampled and
    shown): the greedy policy's mean return at the default context, one seed after another."""
    example = load_example("sb3_ppo_cartpole")
    scores = [example.main(["--timesteps", str(timesteps), "--seed", str(int(s))]) for s in seeds]
    return {"return": np.asarray(scores)}


def platformer_levels(seeds) -> dict[str, np.ndarray]:
    """PPO, 60k steps, four short 24-column levels with narrow gaps and no enemies: per seed, how many
    of the four levels the deterministic policy finishes (return > 30: the flag bonus was reached;
    a death costs 20)."""
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
    train = ppo.make_train(config, env, levels)
    result = measured_jit(jax.vmap(train))(_keys(seeds))
    policy = ppo.make_policy(config, env, levels)
    returns = measured_jit(
        jax.vmap(lambda params, key: evaluate(policy, params, env, levels, 1, key))
    )(result.params, _keys(seeds, 10_000))
    returns = np.asarray(returns).reshape(len(seeds), 4)
    curve = np.asarray(result.metrics["episode_return"])
    return {
        "levels_finished": (returns > 30).sum(axis=1),
        "first_updates": np.nanmean(curve[:, :3], axis=1),
    }


def brax_sac_pendulum(seeds) -> dict[str, np.ndarray]:
    """SAC on Brax's InvertedPendulum, 3,000 steps (2 copies, 500 random warm-up transitions, then an
    update per step): the mean episode return of the first and the last of six logging rows."""
    config = sac.SACConfig(
        total_timesteps=3000,
        num_envs=2,
        hidden_sizes=(64, 64),
        learning_starts=500,
        policy_frequency=1,
        batch_size=128,
        log_every=500,
    )
    from contextrl.envs import brax as family

    env = family.InvertedPendulum(max_steps=200)
    train = sac.make_train(config, env, env.default_context())
    curve = np.asarray(measured_jit(jax.vmap(train))(_keys(seeds)).metrics["episode_return"])
    return {"first_rows": curve[:, 0], "last_rows": curve[:, -1]}


def rna_short_targets(seeds) -> dict[str, np.ndarray]:
    """PPO on the host path, 8,192 steps, RnaDesign on 50 short synthetic targets (12–20 nt) with no
    local improvement: the mean normalised Hamming distance of the first and the last 100 episodes,
    one seed after another."""
    config = ppo.PPOConfig(
        total_timesteps=8192, num_envs=4, num_steps=64, learning_rate=1e-3, episode_log_size=10_000
    )
    contexts = {  # no local improvement: the distance is the agent's own
        "dataset": "synthetic",
        "target_id_last": 50,
        "mutation_threshold": 0.0,
        "state_radius": 4,
    }
    first, last, episodes = [], [], []
    for seed in seeds:
        result = ppo.train_gymnasium(
            config,
            "RnaDesign",
            contexts,
            jax.random.key(int(seed)),
            seed=int(seed),
            synthetic={"lengths": (12, 20), "min_multiloops": 0, "size": 50},
        )
        distance = 1.0 - result.metrics["episodes"]["return"]  # d / length, reward_exponent 1
        first.append(distance[:100].mean())
        last.append(distance[-100:].mean())
        episodes.append(len(distance))
    first, last = np.asarray(first), np.asarray(last)
    return {
        "first_episodes": first,
        "last_episodes": last,
        "last_to_first": last / first,
        "episodes": np.asarray(episodes),
    }


REACH_EPISODES = 32


def _reach_statistics(env, context, act, params, seeds, numerics) -> dict[str, np.ndarray]:
    """Per seed, over REACH_EPISODES evaluation episodes through the core's reset and step (keys
    10,000 + seed): the fraction of episodes that reached a target, the same among those whose first
    target lay ahead of the start pose (x > 0) and among the others, and the mean return.
    ``act(params, obs, ctx, key)`` picks the actions."""

    def episode(params, key):
        reset_key, loop_key = jax.random.split(key)
        state, timestep = env.reset(reset_key, context)
        ahead = jnp.cos(state.physics.target_draws[1]) > 0

        def step(carry, key):
            state, obs, total = carry
            action_key, step_key = jax.random.split(key)
            action = act(params, obs, context, action_key)
            state, timestep = env.step(step_key, state, action, context)
            return (state, timestep.obs, total + timestep.reward), timestep.info["targets_reached"]

        carry = (state, timestep.obs, jnp.zeros((), jnp.float32))
        keys = jax.random.split(loop_key, env.max_steps)
        (_, _, total), reached = jax.lax.scan(step, carry, keys)
        return ahead, reached[-1] > 0, total  # the last step's count is the whole episode's

    def per_seed(params, key):
        keys = jax.random.split(key, REACH_EPISODES)
        return jax.vmap(episode, in_axes=(None, 0))(params, keys)

    ahead, reached, total = (
        np.asarray(x)
        for x in measured_jit(jax.vmap(per_seed), numerics)(params, _keys(seeds, 10_000))
    )
    return {
        "reached": reached.mean(axis=1),
        "reached_ahead": (reached & ahead).sum(axis=1) / ahead.sum(axis=1),
        "reached_behind": (reached & ~ahead).sum(axis=1) / (~ahead).sum(axis=1),
        "return": total.mean(axis=1),
    }


def _reaching_task(name: str):
    """The task, its context, its PPO settings and numerics, as the learning tests run them."""
    from contextrl.envs import brax as family

    common = dict(num_envs=32, num_steps=32, learning_rate=1e-3, hidden_sizes=(64, 64))
    if name == "Fetch":  # targets 2.0–2.1 m away, reached within 2 m: a step toward them
        env = family.Fetch(max_steps=100)
        context = env.context(target_distance=0.1)
        return env, context, ppo.PPOConfig(total_timesteps=50_000, **common), MEASURED_NUMERICS
    if name == "Grasp":  # the default context
        env = family.Grasp(max_steps=100)
        config = ppo.PPOConfig(total_timesteps=150_000, **common)
        return env, env.default_context(), config, MEASURED_NUMERICS
    env = family.Ur5e(max_steps=100)  # targets 0.3–0.4 m from the base, reached within 0.3 m
    context = env.context(target_radius=0.3, target_distance=0.1)
    config = ppo.PPOConfig(total_timesteps=100_000, ent_coef=0.0, log_std_init=-0.5, **common)
    return env, context, config, OLDER_EMITTERS


def _ppo_reach(name: str, seeds, evaluated: bool = True) -> dict[str, np.ndarray]:
    """The training curve's first 5 and last 10 updates' mean episode return, and (``evaluated``)
    :func:`_reach_statistics` of the trained deterministic policy."""
    env, context, config, numerics = _reaching_task(name)
    result = measured_jit(jax.vmap(ppo.make_train(config, env, context)), numerics)(_keys(seeds))
    curve = np.asarray(result.metrics["episode_return"])
    first, last = np.nanmean(curve[:, :5], axis=1), np.nanmean(curve[:, -10:], axis=1)
    statistics = {"first_updates": first, "last_updates": last, "rise": last - first}
    if evaluated:
        policy = ppo.make_policy(config, env, context)
        statistics |= _reach_statistics(env, context, policy, result.params, seeds, numerics)
    return statistics


def _random_reach(name: str, seeds) -> dict[str, np.ndarray]:
    env, context, _, numerics = _reaching_task(name)
    act = get_agent("random").make_policy(None, env, None)
    return _reach_statistics(env, context, act, jnp.zeros(len(seeds)), seeds, numerics)


def ppo_fetch(seeds) -> dict[str, np.ndarray]:
    """PPO on Fetch at target distance 0.1 (100-step episodes), 50k steps (32 copies × 32 steps, lr
    1e-3, 64×64): reach rates and returns of 32 evaluation episodes, the training curve's ends."""
    return _ppo_reach("Fetch", seeds)


def random_fetch(seeds) -> dict[str, np.ndarray]:
    """Uniform random actions on :func:`ppo_fetch`'s evaluation episodes (the same keys)."""
    return _random_reach("Fetch", seeds)


def ppo_ur5e(seeds) -> dict[str, np.ndarray]:
    """PPO on UR5e with target radius 0.3 and distance 0.1 (100-step episodes), 100k steps (32 copies
    × 32 steps, lr 1e-3, 64×64, no entropy bonus, initial log std −0.5): the training curve's ends."""
    return _ppo_reach("Ur5e", seeds, evaluated=False)


def ppo_ur5e_evaluated(seeds) -> dict[str, np.ndarray]:
    """:func:`ppo_ur5e` and the trained policy's reach rates, as :func:`ppo_fetch`'s."""
    return _ppo_reach("Ur5e", seeds)


def random_ur5e(seeds) -> dict[str, np.ndarray]:
    """Uniform random actions on :func:`ppo_ur5e`'s evaluation episodes (the same keys)."""
    return _random_reach("Ur5e", seeds)


def ppo_grasp(seeds) -> dict[str, np.ndarray]:
    """PPO on Grasp at its default context (100-step episodes), 150k steps, otherwise as
    :func:`ppo_fetch`: the training curve's ends (no test: a budget the suite cannot pay)."""
    return _ppo_reach("Grasp", seeds, evaluated=False)


def pointmass_mjx_task():
    """PointMass on MJX, its ball starting 2.5 cm from the target (1 cm outside the target sphere,
    where dm_control's reward pays about 0.36 a step) in 100-step episodes, and PPO's settings."""
    env = crl.make("DmcPointMass", backend="mjx", max_steps=100)
    context = env.context(starting_x=0.025, start_spread=0.0)
    config = ppo.PPOConfig(
        total_timesteps=50_000,
        num_envs=16,
        num_steps=32,
        learning_rate=1e-3,
        hidden_sizes=(64, 64),
        log_std_init=-1.0,
    )
    return env, context, config


def ppo_pointmass_mjx(seeds) -> dict[str, np.ndarray]:
    """PPO on PointMass on MJX (:func:`pointmass_mjx_task`), 50k steps: the mean training return of the
    first 5 and the last 10 updates."""
    env, context, config = pointmass_mjx_task()
    result = measured_jit(jax.vmap(ppo.make_train(config, env, context)))(_keys(seeds))
    curve = np.asarray(result.metrics["episode_return"])
    first, last = np.nanmean(curve[:, :5], axis=1), np.nanmean(curve[:, -10:], axis=1)
    return {"first_updates": first, "last_updates": last}


def random_pointmass_mjx(seeds) -> dict[str, np.ndarray]:
    """Uniform random actions on :func:`ppo_pointmass_mjx`'s task: the mean return of 16 episodes."""
    env, context, _ = pointmass_mjx_task()
    act = get_agent("random").make_policy(None, env, None)
    returns = measured_jit(jax.vmap(lambda key: evaluate(act, None, env, context, 16, key)))(
        _keys(seeds, 10_000)
    )
    return {"return": np.asarray(returns).reshape(len(seeds))}


CASES = {
    "ppo_cartpole": ppo_cartpole,
    "dqn_cartpole": dqn_cartpole,
    "c51_cartpole": c51_cartpole,
    "sac_pendulum": sac_pendulum,
    "purejaxrl_cartpole": purejaxrl_cartpole,
    "sb3_cartpole": sb3_cartpole,
    "platformer_levels": platformer_levels,
    "brax_sac_pendulum": brax_sac_pendulum,
    "rna_short_targets": rna_short_targets,
    "ppo_fetch": ppo_fetch,
    "random_fetch": random_fetch,
    "ppo_ur5e": ppo_ur5e,
    "ppo_ur5e_evaluated": ppo_ur5e_evaluated,
    "random_ur5e": random_ur5e,
    "ppo_grasp": ppo_grasp,
    "ppo_pointmass_mjx": ppo_pointmass_mjx,
    "random_pointmass_mjx": random_pointmass_mjx,
}
