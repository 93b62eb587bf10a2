"""What the return's gradient with respect to the context costs against the rollout it differentiates.

    python benchmarks/bench_context_gradient.py [--horizon 200] [--repeats 50]

For CartPole (a policy that always pushes right, so the pole falls and the terminating step's fraction
is differentiated) and Pendulum (a smooth feedback policy), each compiled once: the milliseconds of the
forward rollout (``crl.return_of_context``), of its gradient with respect to every float feature in
forward mode (``jax.jacfwd``, what ``crl.context_gradient`` runs) and in reverse mode (``jax.grad``,
for comparison), the median of alternating calls so a shared machine's load falls on all alike, and
the ratios to the forward rollout. Compile time is printed apart.
"""

import argparse
import os
import statistics
import time

import jax
import jax.numpy as jnp

import contextrl as crl

KEY = jax.random.key(0)
GAINS = jnp.array([0.0, -3.0, -1.0])
CASES = {
    "CartPole": (lambda obs: 1, {}),
    "Pendulum": (lambda obs: 2.0 * jnp.tanh(GAINS @ obs)[None], {"g": 2.0}),
}


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


def measure(env_id: str, horizon: int, repeats: int) -> list[str]:
    policy, context = CASES[env_id]
    env = crl.make(env_id)
    return_of, values = crl.return_of_context(
        env, policy, env.context(**context), key=KEY, horizon=horizon
    )
    forward, forward_compile = compiled(return_of, values)
    forward_mode, gradient_compile = compiled(jax.jacfwd(return_of), values)
    reverse_mode, _ = compiled(jax.grad(return_of), values)
    times = {forward: [], forward_mode: [], reverse_mode: []}
    for _ in range(repeats):  # alternating, so all see the same load
        for function, taken in times.items():
            taken.append(seconds(function, values))
    forward_s, forward_mode_s, reverse_mode_s = (statistics.median(t) for t in times.values())
    return [
        env_id,
        f"{len(values)}",
        f"{forward_s * 1e3:.3f}",
        f"{forward_mode_s * 1e3:.3f}",
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
    rows = [measure(env_id, args.horizon, args.repeats) for env_id in CASES]
    print(
        f"{args.horizon}-step rollout, median of {args.repeats} calls; jax {jax.__version__} on "
        f"{jax.devices()[0].platform}; load average {start_load} at the start, {load()} at the end"
    )
    header = [
        "env",
        "features",
        "forward ms",
        "gradient ms",
        "gradient / forward",
        "reverse mode / forward",
        "compile s (f / g)",
    ]
    print("| " + " | ".join(header) + " |")
    print("|" + "|".join(" --- " for _ in header) + "|")
    for row in rows:
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
