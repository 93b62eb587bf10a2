"""Whole-episode returns on MJX against dm_control, run by hand (minutes per task on two cores, beyond
the suite's budget); docs/families/dmc.md quotes what it printed.

    python -m tests.helpers.mjx_episodes                  # all five domains, and the trained policy
    python -m tests.helpers.mjx_episodes DmcPointMass     # some

    python -m tests.helpers.mjx_episodes --same-starts DmcQuadruped
    python -m tests.helpers.mjx_episodes DmcQuadruped --seed 10   # other draws, default context

The suite checks that 10 steps from the same state agree within float32 tolerances
(tests/envs/dmc/test_dmc_mjx.py). Over 1,000 steps the two simulators' trajectories part (float32
against float64, contacts), and their starts come from different generators, so what should agree is
the distribution of returns: per task and context, uniform random actions for EPISODES episodes on
each, and the Welch 95% interval of the difference of their mean returns. The trained policy is PPO
on PointMass as the learning test trains it (tests/helpers/learning.py), acting deterministically
from starts spread ±1.5 cm about its training start. ``--same-starts`` instead steps both from
dm_control's own starts with the same random actions for 300 steps and compares each episode's
return (and, for Quadruped, the two simulators' start distributions).
"""

from __future__ import annotations

import argparse
import time

from contextrl.xla_flags import xla_cpu_workaround

xla_cpu_workaround()  # as the test session does, before JAX starts

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

import contextrl as crl  # noqa: E402
from contextrl.agents import evaluate_episodes, get_agent, ppo  # noqa: E402
from contextrl.envs import DMC_ENVIRONMENTS  # noqa: E402
from tests.envs.dmc.test_dmc_mjx import host_start, mjx_start  # noqa: E402
from tests.helpers import learning  # noqa: E402

EPISODES = 32
CHANGED = {"actuator_strength": 0.5, "viscosity": 1.0}  # weaker motors in a viscous medium


def host_returns(host, context, act, episodes: int, steps: int, seed: int) -> np.ndarray:
    """Returns of ``episodes`` episodes of ``steps`` steps on dm_control (fewer where one ends);
    ``act(obs, key)`` picks the actions."""
    rng, key = np.random.default_rng(seed), jax.random.key(seed)
    returns = []
    for _ in range(episodes):
        obs, total = host.reset_physics(context, rng), 0.0
        for _ in range(steps):
            key, action_key = jax.random.split(key)
            obs, reward, terminated = host.step_physics(np.asarray(act(obs, action_key)))
            total += reward
            if terminated:
                break
        returns.append(total)
    return np.asarray(returns)


def compare(label: str, ours: np.ndarray, theirs: np.ndarray) -> None:
    """One line: both means, the Welch 95% interval of MJX − dm_control and its p-value."""
    test = stats.ttest_ind(ours, theirs, equal_var=False)
    low, high = test.confidence_interval(0.95)
    print(
        f"  {label:<34} MJX {ours.mean():8.2f} ± {ours.std(ddof=1):6.2f}   dm_control "
        f"{theirs.mean():8.2f} ± {theirs.std(ddof=1):6.2f}   difference "
        f"{ours.mean() - theirs.mean():7.2f} [{low:.2f}, {high:.2f}]  p {test.pvalue:.2f}",
        flush=True,
    )


def random_row(host, env, label: str, values: dict, seed: int = 0) -> None:
    """Uniform random actions on both simulators at the context ``values`` (MJX's keys from
    ``seed``, dm_control's generator from ``seed + 1``)."""
    context = env.context(**values)
    act = get_agent("random").make_policy(None, env, None)
    start = time.perf_counter()
    run = jax.jit(lambda key: evaluate_episodes(act, None, env, context, EPISODES, key))
    ours = np.asarray(run(jax.random.key(seed))).ravel()
    mjx_seconds = time.perf_counter() - start
    sample = jax.jit(env.action_space.sample)
    theirs = host_returns(
        host,
        host.context(**values),
        lambda obs, key: sample(key),
        EPISODES,
        env.max_steps,
        seed + 1,
    )
    compare(f"random, {label} ({mjx_seconds:.0f} s)", ours, theirs)


def random_actions(name: str, seed: int = 0, changed_too: bool = True) -> None:
    host, env = crl.make(name), crl.make(name, backend="mjx")
    changed = {k: v for k, v in CHANGED.items() if k in env.context_space.names}
    random_row(host, env, "default", {}, seed)
    if changed_too:
        label = ", ".join(f"{k} {v}" for k, v in changed.items())
        random_row(host, env, label, changed, seed)


def trained_pointmass() -> None:
    """PPO trained on MJX (seed 0), its deterministic policy on both simulators."""
    env, context, config = learning.pointmass_mjx_task()
    result = learning.measured_jit(ppo.make_train(config, env, context))(jax.random.key(0))
    spread = env.context(starting_x=0.025, start_spread=0.05)  # ±1.5 cm in a 0.3 m arena
    policy = ppo.make_policy(config, env, context)
    run = jax.jit(lambda key: evaluate_episodes(policy, result.params, env, spread, EPISODES, key))
    ours = np.asarray(run(jax.random.key(0))).ravel()
    act = jax.jit(lambda obs, key: policy(result.params, obs, spread, key))
    theirs = host_returns(crl.make("DmcPointMass"), spread, act, EPISODES, env.max_steps, 1)
    compare(f"PPO, {env.max_steps}-step episodes", ours, theirs)


def same_starts(name: str, episodes: int = 48, steps: int = 300) -> None:
    """From dm_control's own starts, the same uniform random actions on both simulators: how far
    apart each episode's return ends."""
    host, env = crl.make(name), crl.make(name, backend="mjx")
    context = env.default_context()
    shape = (episodes, steps, *env.action_space.shape)
    actions = np.random.default_rng(7).uniform(-1, 1, shape).astype(np.float32)
    rng, starts, theirs = np.random.default_rng(3), [], []
    for episode in actions:
        host.reset_physics(host.context(), rng)
        starts.append(host_start(name, env, host))
        theirs.append(sum(host.step_physics(action)[1] for action in episode))

    def episode(qpos, qvel, act, goal, actions):
        def step(state, action):
            state, reward, _ = env.transition(None, state, action, context)
            return state, reward

        return jax.lax.scan(step, mjx_start(env, context, qpos, qvel, act, goal), actions)[1].sum()

    start = time.perf_counter()
    columns = (jnp.asarray(np.stack(c), jnp.float32) for c in zip(*starts, strict=True))
    ours = np.asarray(jax.jit(jax.vmap(episode))(*columns, jnp.asarray(actions)))
    gap = np.abs(ours - np.asarray(theirs))
    print(
        f"  same starts, {episodes} episodes of {steps} steps ({time.perf_counter() - start:.0f} s): "
        f"mean return MJX {ours.mean():.2f}, dm_control {np.mean(theirs):.2f}; per episode "
        f"|MJX − dm_control| median {np.median(gap):.3g}, max {gap.max():.3g}",
        flush=True,
    )


def quadruped_starts(count: int = 2000) -> None:
    """Quadruped's start, drawn by each simulator: torso uprightness and height, compared by the
    two-sample Kolmogorov–Smirnov test (its random orientation decides whether it lands upright)."""
    host, env = crl.make("DmcQuadruped"), crl.make("DmcQuadruped", backend="mjx")
    rng, theirs = np.random.default_rng(11), []
    for _ in range(count):
        host.reset_physics(host.context(), rng)
        named = host.physics.named.data
        theirs.append((named.xmat["torso", "zz"], named.qpos["root"][2]))
    context = env.default_context()
    states = jax.jit(jax.vmap(lambda key: env.init(key, context)))(
        jax.random.split(jax.random.key(5), count)
    )
    ours = np.stack(
        [
            np.asarray(jax.vmap(env.upright)(states.data)),
            np.asarray(states.data.qpos[:, env.qpos_address("root") + 2]),
        ],
        axis=1,
    )
    for column, label in enumerate(("upright", "height")):
        a, b = ours[:, column], np.asarray(theirs)[:, column]
        print(
            f"  starts, {label}: mean MJX {a.mean():.4f}, dm_control {b.mean():.4f}; "
            f"Kolmogorov–Smirnov p {stats.ks_2samp(a, b).pvalue:.2f}; quantiles 0/10/50/90/100 % "
            f"MJX {np.quantile(a, [0, 0.1, 0.5, 0.9, 1]).round(3).tolist()}, dm_control "
            f"{np.quantile(b, [0, 0.1, 0.5, 0.9, 1]).round(3).tolist()}",
            flush=True,
        )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=list(DMC_ENVIRONMENTS))
    parser.add_argument("--same-starts", action="store_true", help="from dm_control's starts")
    parser.add_argument(
        "--seed", type=int, default=0, help="other draws: the default context only, from this seed"
    )
    args = parser.parse_args(argv)
    if args.same_starts:
        for name in args.names:
            print(name, flush=True)
            same_starts(name)
            if name == "DmcQuadruped":
                quadruped_starts()
        return
    print(f"{EPISODES} episodes per simulator and row; MJX − dm_control, Welch 95% interval")
    for name in args.names:
        print(name, flush=True)
        random_actions(name, args.seed, changed_too=args.seed == 0)
    if "DmcPointMass" in args.names and args.seed == 0:
        trained_pointmass()


if __name__ == "__main__":
    main()
