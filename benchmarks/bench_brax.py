"""Steps per second of the Brax family, every copy with its own physical system, against brax itself.

    python benchmarks/bench_brax.py [--envs Ant,HalfCheetah] [--sizes 1,64,256,1024] [--steps 20]

1. Per-copy contexts against one shared system: Ant and HalfCheetah at 256 copies, each copy with its
   own gravity, friction, torso mass and actuator strength, against brax's own environment
   (``brax.envs.create``: the same time limit and auto-reset) vmapped with one system for all copies,
   in the same loop and the same run. Also with MuJoCo's medium model on (``fluid=True``, which adds
   the ``viscosity`` feature), which MJX then evaluates at every physics step.
2. Steps/s of every environment at 1, 64, 256 and 1,024 copies (MJX), with the compile time.
3. Changing context values never recompiles: one compiled step is called with new values of every
   feature and the number of traces is counted.
"""

import argparse

import jax
import jax.numpy as jnp
from _scan import observing, random_rollout, steps_per_second

import contextrl as crl
from contextrl.envs import brax as family

SIZES = (1, 64, 256, 1024)


def per_copy_contexts(env, n: int):
    """``n`` contexts spread around the default: gravity, friction, torso mass and actuator strength."""
    default = env.default_context()
    spec = {
        "gravity": crl.Uniform(5.0, 15.0),
        "actuator_strength": crl.Uniform(0.5, 1.5),
    }
    if "friction" in env.context_space.names:
        spec["friction"] = crl.Uniform(0.5, 1.5)
    if "mass_torso" in env.context_space.names:
        torso = float(default.mass_torso)
        spec["mass_torso"] = crl.Uniform(0.5 * torso, 1.5 * torso)
    return crl.sample(env, spec, n, jax.random.key(0))


def ours(env, n: int):
    contexts = per_copy_contexts(env, n)
    return random_rollout(*observing(env), env.action_space.sample, contexts, STEPS)


def brax_shared(env, n: int):
    """brax's own environment: one system for every copy, its time limit and auto-reset wrappers."""
    from brax import envs as brax_envs

    stock = brax_envs.create(env.brax_name, episode_length=env.max_steps, backend=env.backend)

    def reset(key, _):
        state = stock.reset(key)
        return state, state.obs

    def step(key, state, action, _):
        state = stock.step(state, action)
        return state, state.obs

    return random_rollout(reset, step, env.action_space.sample, jnp.zeros(n), STEPS)


def compare_with_brax(names, n: int) -> None:
    print(f"\nPer-copy contexts vs brax's one shared system, {n} copies, {STEPS} steps (MJX)")
    print(
        f"{'env':>14} {'brax shared':>12} {'ours':>10} {'ratio':>6} {'ours, fluid':>15} {'ratio':>6}"
    )
    for name in names:
        env = getattr(family, name)()
        _, theirs = steps_per_second(brax_shared(env, n), n, STEPS)
        _, mine = steps_per_second(ours(env, n), n, STEPS)
        _, wet = steps_per_second(ours(getattr(family, name)(fluid=True), n), n, STEPS)
        print(
            f"{name:>14} {theirs:>12.4g} {mine:>10.4g} {mine / theirs:>6.2f} {wet:>15.4g}"
            f" {wet / theirs:>6.2f}",
            flush=True,
        )


def no_recompilation(name: str) -> None:
    """One compiled step, called with every feature moved to a new value: traced once."""
    env = getattr(family, name)()
    traces = []

    def step(key, state, action, context):
        traces.append(1)
        return env.step(key, state, action, context)

    compiled = jax.jit(step)
    key = jax.random.key(0)
    state, _ = jax.jit(env.reset)(key, env.default_context())
    action = jnp.zeros(env.action_space.shape)
    compiled(key, state, action, env.default_context())
    for feature_name, f in env.context_space.features.items():
        value = f.upper if f.kind != "categorical" else (f.default + 1) % len(f.choices)
        compiled(key, state, action, env.context(**{feature_name: value}))
    print(
        f"\n{name}: one compiled step called with {len(env.context_space) + 1} different contexts,"
        f" traced {len(traces)} time(s)",
        flush=True,
    )


def main() -> None:
    global STEPS
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", default=",".join(c.__name__ for c in family.ENVIRONMENTS))
    parser.add_argument("--sizes", default=",".join(map(str, SIZES)))
    parser.add_argument("--steps", type=int, default=20, help="random steps per copy per timing")
    parser.add_argument("--skip-compare", action="store_true")
    args = parser.parse_args()
    STEPS = args.steps
    names = args.envs.split(",")
    sizes = [int(s) for s in args.sizes.split(",")]
    print(
        f"jax {jax.__version__} on {jax.devices()[0].platform}, {STEPS} random steps per copy",
        flush=True,
    )
    no_recompilation("InvertedPendulum")
    if not args.skip_compare:
        compare_with_brax([n for n in ("Ant", "HalfCheetah") if n in names], 256)
    print("\nEvery environment, each copy with its own context (MJX)")
    print(f"{'env':>24} {'copies':>7} {'compile s':>10} {'steps/s':>10}")
    for name in names:
        env = getattr(family, name)()
        for n in sizes:
            compile_s, rate = steps_per_second(ours(env, n), n, STEPS, repeats=2)
            print(f"{name:>24} {n:>7} {compile_s:>10.1f} {rate:>10.3g}", flush=True)


STEPS = 20

if __name__ == "__main__":
    main()
