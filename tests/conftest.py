"""The test session sets the XLA:CPU flag a user of large vmapped training sets (see README)."""

from contextrl.xla_flags import xla_cpu_workaround

xla_cpu_workaround()  # before any test starts JAX's CPU backend
