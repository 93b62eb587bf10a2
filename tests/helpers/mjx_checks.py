"""The public checker on every dm_control task on MJX, run by hand (minutes per task on two cores,
beyond the suite's budget); docs/families/dmc.md quotes what it printed.

    python -m tests.helpers.mjx_checks                  # all five domains
    python -m tests.helpers.mjx_checks DmcPointMass     # some

The suite checks every feature of these tasks against dm_control itself
(tests/envs/dmc/test_dmc_mjx.py); this adds what only the checker looks for: no undeclared effect, no
non-finite state at any probed value inside the bounds, no recompilation for new context values, the
same trajectory from the same key. Rollouts are 20 steps and effects are looked for over 10 (MJX
contacts at the bounds make every step slow on a CPU), so the 1,000-step time limit is not reached
here (the core's ContextualEnv truncates every JAX family alike, checked on the others).
"""

from __future__ import annotations

import argparse
import dataclasses
import time

from contextrl.xla_flags import xla_cpu_workaround

xla_cpu_workaround()  # as the test session does, before JAX starts

import jax.numpy as jnp  # noqa: E402

import contextrl as crl  # noqa: E402
from contextrl.envs import DMC_ENVIRONMENTS  # noqa: E402
from contextrl.testing import check_env  # noqa: E402


def effect_bases(name: str, env):
    """Contexts the effects are also probed from: PointMass's ball starting on its target (its
    reward falls below 1e-6 beyond about 5 cm from the target, which random actions never reach)."""
    if name != "DmcPointMass":
        return None
    default = env.default_context()
    on_target = dataclasses.replace(
        default,
        start_spread=jnp.float32(0.0),
        starting_x=default.target_x,
        starting_y=default.target_y,
    )
    return env.context_space.stack([on_target])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=list(DMC_ENVIRONMENTS))
    args = parser.parse_args(argv)
    for name in args.names:
        env = crl.make(name, backend="mjx")
        start = time.perf_counter()
        check_env(
            env, num_contexts=4, steps=20, effect_steps=10, effect_bases=effect_bases(name, env)
        )
        print(f"{name}: passed in {time.perf_counter() - start:.0f} s", flush=True)


if __name__ == "__main__":
    main()
