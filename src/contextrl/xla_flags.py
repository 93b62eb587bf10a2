"""XLA:CPU settings the ``contextrl`` command and the experiment runner apply before JAX starts.

Importing contextrl changes no process-wide setting. A library user who trains many agents in one
vmapped call sets the flag before JAX computes anything: ``export
XLA_FLAGS=--xla_cpu_enable_concurrency_optimized_scheduler=false`` in the shell, or call
:func:`xla_cpu_workaround` first thing in the script.
"""

import os


def xla_cpu_workaround() -> None:
    """Turn off XLA:CPU's concurrency-optimised scheduler unless XLA_FLAGS already decides.

    With it, large vmapped programs can wedge forever on jaxlib 0.10, every pool thread idle: 128 PPO
    agents in one call, or Brax's Walker2d at 1,024 copies on 2 cores (brax's own environment too: two
    batched LAPACK Cholesky factorisations run at once, each waiting for pool threads the other
    holds). Takes effect only if called before JAX creates its CPU backend (importing contextrl does
    not create it): the CLI's ``main``, the experiment runner and its Ray workers call it.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_enable_concurrency_optimized_scheduler" not in flags:
        option = "--xla_cpu_enable_concurrency_optimized_scheduler=false"
        os.environ["XLA_FLAGS"] = f"{flags} {option}".strip()
