"""What the return's gradient with respect to the context costs against the rollout it differentiates.

    python benchmarks/bench_context_gradient.py [--horizon 200] [--repeats 50]

For CartPole (a policy that always pushes right, so the pole falls and the terminating step's fraction
is differentiated) and Pendulum (a smooth feedback policy), and for each under an agent's policy as the
sensitivity report differentiates it (PPO's default networks on CartPole, SAC's on Pendulum, freshly
initialised, the context shown: ``context_gradient(..., params=)``), each compiled once: the
milliseconds of the rollout (``crl.return_of_context``) and of its gradient with respect to every
float feature as ``crl.context_gradient`` takes it (reverse mode for an environment that never
terminates, forward mode otherwise), and the ratios of both modes to the rollout: medians of
alternating calls, so a shared machine's load falls on all alike. Compile time is printed apart.
"""

import argparse
import os
import statistics
import time

import jax
import jax.numpy as jnp

import contextrl as crl
from contextrl.agents import ppo, sac
from contextrl.core.gradient import differentiated, never_terminates

KEY = jax.random.key(0)
GAINS = jnp.array([0.0, -3.0, -1.0])
CASES = {
    "CartPole": (lambda obs: 1, {}),
    "Pendulum": (lambda obs: 2.0 * jnp.tanh(GAINS @ obs)[None], {"g": 2.0}),
}
AGENTS = {"CartPole": (ppo, ppo.PPOConfig), "Pendulum": (sac, sac.SACConfig)}


def agent_case(env_id: str):
    """(name, env, policy, params, context) for an agent's freshly initialised policy."""
    module, config_type = AGENTS[env_id]
    config = config_type(variant="concat_all")
    env = crl.make(env_id)
    context = env.default_context()
    params = module.init_params(config, env, context, jax.random.key(1))
    widths = " × ".join(str(w) for w in config.hidden_sizes)
    policy = module.make_policy(config, env, context)
    return (
        f"{env_id}, {module.__name__.rsplit('.', 1)[1].upper()} policy {widths}",
        env,
        policy,
        params,
        context,
    )


def load() -> str:
    try:
        return f"{os.getloadavg()[0]:.1f}"
    except OSError:
        return "unknown"


def compiled(function, values) -> tuple[object, float]:
    """``function`` jitted, and the seconds its first call took (compilation included)."""
    function = jax.jit(function)
    start = time.perf_counter()
    jax.block_until_ready(function(values))
    return function, time.perf_counter() - start


def seconds(function, values) -> float:
    start = time.perf_counter()
    jax.block_until_ready(function(values))
    return time.perf_counter() - start


def measure(name, env, policy, params, context, horizon: int, repeats: int) -> list[str]:
    return_of, values = crl.return_of_context(
        env, policy, context, key=KEY, horizon=horizon, params=params
    )
    forward, forward_compile = compiled(return_of, values)
    chosen, gradient_compile = compiled(differentiated(env, return_of), values)
    forward_mode, _ = compiled(jax.jacfwd(return_of), values)
    reverse_mode, _ = compiled(jax.grad(return_of), values)
    times = {forward: [], chosen: [], forward_mode: [], reverse_mode: []}
    for _ in range(repeats):  # alternating, so all see the same load
        for function, taken in times.items():
            taken.append(seconds(function, values))
    forward_s, chosen_s, forward_mode_s, reverse_mode_s = (
        statistics.median(t) for t in times.values()
    )
    mode = "reverse" if never_terminates(env) else "forward"
    return [
        name,
        f"{len(values)}",
        f"{forward_s * 1e3:.3f}",
        mode,
        f"{chosen_s * 1e3:.3f}",
        f"{chosen_s / forward_s:.1f}×",
        f"{forward_mode_s / forward_s:.1f}×",
        f"{reverse_mode_s / forward_s:.1f}×",
        f"{forward_compile:.2f} / {gradient_compile:.2f}",
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--horizon", type=int, default=200, help="steps of the rollout")
    parser.add_argument("--repeats", type=int, default=50, help="timed calls of each, alternating")
    args = parser.parse_args()
    start_load = load()
    envs = {env_id: crl.make(env_id) for env_id in CASES}
    cases = [
        (env_id, envs[env_id], policy, None, envs[env_id].context(**context))
        for env_id, (policy, context) in CASES.items()
    ]
    cases += [agent_case(env_id) for env_id in AGENTS]
    rows = [measure(*case, args.horizon, args.repeats) for case in cases]
    print(
        f"{args.horizon}-step rollout, median of {args.repeats} calls; jax {jax.__version__} on "
        f"{jax.devices()[0].platform}; load average {start_load} at the start, {load()} at the end"
    )
    header = [
        "env",
        "features",
        "rollout ms",
        "context_gradient's mode",
        "gradient ms",
        "gradient / rollout",
        "forward mode / rollout",
        "reverse mode / rollout",
        "compile s (f / g)",
    ]
    print("| " + " | ".join(header) + " |")
    print("|" + "|".join(" --- " for _ in header) + "|")
    for row in rows:
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
