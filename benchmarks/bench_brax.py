"""Steps per second of the Brax family, every copy with its own physical system, against brax itself.

    python benchmarks/bench_brax.py [--envs Ant,HalfCheetah] [--reaching Fetch,Grasp,Ur5e] [--sizes 1,64,256,1024]

Everything is stepped through the project's one stepping path, ``crl.with_contexts(env, contexts)``
with ``reset_copies``/``step_copies`` (what the agents and the gymnasium vector face run): copy i keeps
context i of a batch drawn per copy, episodes end and restart (a new context chosen) inside the loop.

1. Per-copy contexts against one shared system: Ant and HalfCheetah at 256 copies, each copy with its
   own gravity, friction, torso mass and actuator strength, against brax's own environment
   (``brax.envs.create``: ``get_environment`` with brax's time limit and auto-reset) vmapped with one
   system for all copies. Both are compiled first, then timed in alternating calls, so the load of a
   shared machine falls on both alike.
2. Steps/s of every environment at 1, 64, 256 and 1,024 copies (MJX), random actions, beside brax's own
   environment with one shared system at the same size (MJX's solver runs until every copy of a batch
   converges, so some tasks are slow on a CPU for brax too: the ratio tells ours from MJX), with the compile
   time (XLA's backend compilations, summed from ``jax.monitoring``) and a check that new context values
   never recompile: the compiled rollout takes the contexts as an argument and is called again with a
   second, independently drawn batch; the jitted function's cache and XLA's compilation count must not
   grow.
3. The target-reaching tasks (Fetch, Grasp, UR5e) the same way, with no brax column (brax has not had them
   since 2023), compiled twice: with XLA's defaults and with ``xla_cpu_use_fusion_emitters`` off for
   that program (``jax.jit``'s ``compiler_options``). XLA:CPU's fusion emitters make MJX's forward
   kinematics of a long serial chain cost exponentially more per level (UR5e's six-link arm).

Runs with XLA:CPU's concurrency-optimised scheduler off (``contextrl.xla_flags``): with it, Walker2d at
1,024 copies never finishes on 2 cores, for brax's own environment as for ours (jaxlib 0.10.2 runs two
batched LAPACK Cholesky factorisations of MJX's Newton solver at once; each splits its batch over the
2-thread pool and waits for the other's thread).
"""

import argparse
import os
import time

import jax
import jax.numpy as jnp
from _contextual import contextual_rollout

import contextrl as crl
from contextrl.envs import brax as family
from contextrl.xla_flags import xla_cpu_workaround

SIZES = (1, 64, 256, 1024)
COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
compilations: list[float] = []  # seconds of every XLA compilation in this process
jax.monitoring.register_event_duration_secs_listener(
    lambda event, seconds, **_: compilations.append(seconds) if event == COMPILE_EVENT else None
)


def per_copy_contexts(env, n: int, key):
    """``n`` contexts spread around the default: gravity, friction, torso mass and actuator strength."""
    spec = {"gravity": crl.Uniform(5.0, 15.0), "actuator_strength": crl.Uniform(0.5, 1.5)}
    if "friction" in env.context_space.names:
        spec["friction"] = crl.Uniform(0.5, 1.5)
    if "mass_torso" in env.context_space.names:
        torso = env.context_space.features["mass_torso"].default
        spec["mass_torso"] = crl.Uniform(0.5 * torso, 1.5 * torso)
    if not env.has_gravity:
        del spec["gravity"]
    return crl.sample(env, spec, n, key)


def reaching_contexts(env, n: int, key):
    """``n`` contexts of a target-reaching task around its paper defaults: gravity, friction, torso mass
    (where the task has one), motor strength and target distance."""
    features = env.context_space.features
    strength, distance = features["actuator_strength"].default, features["target_distance"].default
    spec = {
        "gravity": crl.Uniform(5.0, 15.0),
        "friction": crl.Uniform(0.3, 1.0),
        "torso_mass": crl.Uniform(0.5, 2.0),
        "actuator_strength": crl.Uniform(0.5 * strength, 1.5 * strength),
        "target_distance": crl.Uniform(0.5 * distance, 1.5 * distance),
    }
    return crl.sample(env, {name: spec[name] for name in spec if name in features}, n, key)


def brax_rollout(env, n: int, steps: int):
    """jit((key, unused) → checksum): brax's own environment, one system for every copy, vmapped."""
    from brax import envs as brax_envs

    stock = brax_envs.create(env.brax_name, episode_length=env.max_steps, backend=env.backend)

    def run(key, _):
        reset_key, key = jax.random.split(key)
        state = jax.vmap(stock.reset)(jax.random.split(reset_key, n))

        def body(carry, action_key):
            state, total = carry
            actions = jax.vmap(env.action_space.sample)(jax.random.split(action_key, n))
            state = jax.vmap(stock.step)(state, actions)
            return (state, total + jnp.sum(state.obs)), None

        (_, total), _ = jax.lax.scan(
            body, (state, jnp.sum(state.obs)), jax.random.split(key, steps)
        )
        return total

    return jax.jit(run)


def first_call(run, argument) -> float:
    """Compiles ``run`` by calling it once; returns the seconds XLA spent compiling."""
    before = len(compilations)
    run(jax.random.key(0), argument).block_until_ready()
    return sum(compilations[before:])


def seconds_of(run, key, argument) -> float:
    start = time.perf_counter()
    run(key, argument).block_until_ready()
    return time.perf_counter() - start


def best_rates(sides, steps_per_call: int, rounds: int) -> list[float]:
    """Steps/s of each compiled side, the best of ``rounds`` calls made in turn (side 1, side 2, …,
    side 1, …), so a shared machine's load falls on every side alike."""
    best = [float("inf")] * len(sides)
    for i in range(rounds):
        for side, (run, argument) in enumerate(sides):
            best[side] = min(best[side], seconds_of(run, jax.random.key(i + 1), argument))
    return [steps_per_call / s for s in best]


def compare_with_brax(names, n: int, steps: int, rounds: int) -> None:
    print(
        f"\nPer-copy contexts vs brax's one shared system, {n} copies, {steps} steps per call, best of"
        f" {rounds} alternating calls (MJX); 'ours, default' is the same compiled program given the"
        " default context in every copy"
    )
    print(
        f"{'env':>14} {'brax shared':>12} {'ours':>10} {'ratio':>6} {'ours, default':>14} {'ratio':>6}"
    )
    for name in names:
        env = getattr(family, name)()
        ours = contextual_rollout(env, n, steps)
        defaults = env.context_space.stack([env.default_context()] * n)
        sides = (
            (brax_rollout(env, n, steps), jnp.zeros(())),
            (ours, per_copy_contexts(env, n, jax.random.key(1))),
            (ours, defaults),
        )
        for run, argument in sides[:2]:
            first_call(run, argument)
        theirs, mine, default = best_rates(sides, n * steps, rounds)
        print(
            f"{name:>14} {theirs:>12.4g} {mine:>10.4g} {mine / theirs:>6.2f} {default:>14.4g}"
            f" {default / theirs:>6.2f}",
            flush=True,
        )


def steps_for(n: int, rate: float | None, seconds: float) -> int:
    """Steps per timed call: 20 at first, then about ``seconds`` at the rate of the previous size
    (at least 2, at most 100): MJX tasks differ by 100x in speed on a CPU."""
    if rate is None:
        return 20
    return int(max(2, min(100, rate * seconds / n)))


def table(names, sizes, seconds: float, rounds: int) -> None:
    print(
        "\nEvery environment, each copy with its own context, through ContextualEnv.step_copies (MJX),"
        f" beside brax's own environment with one shared system (best of {rounds} alternating calls)"
    )
    print(
        f"{'env':>24} {'copies':>7} {'steps':>6} {'compile s':>10} {'steps/s':>10} {'brax':>10}"
        f" {'ratio':>6} {'recompiles on new contexts':>27}"
    )
    for name in names:
        env = getattr(family, name)()
        rate = None
        for n in sizes:
            steps = steps_for(n, rate, seconds)
            run, stock = contextual_rollout(env, n, steps), brax_rollout(env, n, steps)
            first, second = (per_copy_contexts(env, n, jax.random.key(k)) for k in (1, 2))
            compile_s = first_call(run, first)
            first_call(stock, jnp.zeros(()))
            before = len(compilations)
            theirs, rate = best_rates(((stock, jnp.zeros(())), (run, second)), n * steps, rounds)
            recompiles = len(compilations) - before + run._cache_size() - 1
            print(
                f"{name:>24} {n:>7} {steps:>6} {compile_s:>10.1f} {rate:>10.3g} {theirs:>10.3g}"
                f" {rate / theirs:>6.2f} {recompiles:>27}",
                flush=True,
            )


def reaching_table(names, sizes, seconds: float, rounds: int) -> None:
    print(
        "\nThe target-reaching tasks (no brax counterpart), each copy with its own context, compiled"
        f" with XLA's defaults and with the fusion emitters off (best of {rounds} alternating calls)"
    )
    print(
        f"{'env':>8} {'copies':>7} {'steps':>6} {'compile s':>10} {'steps/s':>10}"
        f" {'emitters off: compile s':>24} {'steps/s':>10} {'recompiles on new contexts':>27}"
    )
    for name in names:
        env = getattr(family, name)()
        rate = None
        for n in sizes:
            steps = steps_for(n, rate, seconds)
            runs = [
                contextual_rollout(env, n, steps, options)
                for options in (None, {"xla_cpu_use_fusion_emitters": False})
            ]
            first, second = (reaching_contexts(env, n, jax.random.key(k)) for k in (1, 2))
            compile_s = [first_call(run, first) for run in runs]
            before = len(compilations)
            rates = best_rates([(run, second) for run in runs], n * steps, rounds)
            recompiles = len(compilations) - before + sum(run._cache_size() - 1 for run in runs)
            rate = max(rates)
            print(
                f"{name:>8} {n:>7} {steps:>6} {compile_s[0]:>10.1f} {rates[0]:>10.3g}"
                f" {compile_s[1]:>24.1f} {rates[1]:>10.3g} {recompiles:>27}",
                flush=True,
            )


def main() -> None:
    xla_cpu_workaround()  # before the first JAX computation starts XLA's CPU backend
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", default=",".join(c.__name__ for c in family.ENVIRONMENTS))
    parser.add_argument("--sizes", default=",".join(map(str, SIZES)))
    parser.add_argument("--seconds", type=float, default=2.0, help="aimed length of a timed call")
    parser.add_argument("--compare-steps", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=3, help="alternating timed calls per side")
    parser.add_argument("--skip-compare", action="store_true")
    parser.add_argument("--skip-table", action="store_true")
    parser.add_argument(
        "--reaching", default=",".join(c.__name__ for c in family.REACHING_ENVIRONMENTS)
    )
    args = parser.parse_args()
    names = args.envs.split(",") if args.envs else []
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(
        f"jax {jax.__version__} on {jax.devices()[0].platform}, {os.cpu_count()} cores shared with other"
        f" jobs (load average at start {load})",
        flush=True,
    )
    if not args.skip_compare:
        compared = [n for n in ("Ant", "HalfCheetah") if n in names]
        compare_with_brax(compared, 256, args.compare_steps, args.rounds)
    if not args.skip_table:
        table(names, [int(s) for s in args.sizes.split(",")], args.seconds, args.rounds)
    if args.reaching:
        reaching = args.reaching.split(",")
        reaching_table(reaching, [int(s) for s in args.sizes.split(",")], args.seconds, args.rounds)
    print(f"\nload average at the end: {', '.join(f'{x:.1f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
