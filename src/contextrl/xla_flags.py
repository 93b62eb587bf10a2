"""XLA:CPU settings the ``contextrl`` command and the experiment runner apply before JAX starts.

Importing contextrl changes no process-wide setting. A library user who trains many agents in one
vmapped call sets the flag before JAX computes anything: ``export
XLA_FLAGS=--xla_cpu_enable_concurrency_optimized_scheduler=false`` in the shell, or call
:func:`xla_cpu_workaround` first thing in the script.
"""

import os


def xla_cpu_workaround() -> None:
    """Turn off XLA:CPU's concurrency-optimised scheduler unless XLA_FLAGS already decides.

    With it, large vmapped training programs (e.g. 128 PPO agents in one call, jaxlib 0.10) can wedge
    forever: every pool thread idle, the executable never completing. Takes effect only if called before
    JAX creates its CPU backend: the CLI's ``main``, the experiment runner and its Ray workers call it.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_enable_concurrency_optimized_scheduler" not in flags:
        option = "--xla_cpu_enable_concurrency_optimized_scheduler=false"
        os.environ["XLA_FLAGS"] = f"{flags} {option}".strip()
