"""XLA:CPU settings contextrl applies before JAX starts its CPU backend (importing contextrl does it)."""

import os


def xla_cpu_workaround() -> None:
    """Turn off XLA:CPU's concurrency-optimised scheduler unless XLA_FLAGS already decides.

    With it, large vmapped training programs (e.g. 128 PPO agents in one call, jaxlib 0.10) can wedge
    forever: every pool thread idle, the executable never completing. Takes effect only if called before
    JAX creates its CPU backend, which is why importing contextrl calls it first.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_enable_concurrency_optimized_scheduler" not in flags:
        option = "--xla_cpu_enable_concurrency_optimized_scheduler=false"
        os.environ["XLA_FLAGS"] = f"{flags} {option}".strip()
