"""The test session sets the XLA:CPU flag a user of large vmapped training sets (see README); test
files that start a local Ray stop it when they end."""

import sys

import pytest

from contextrl.xla_flags import xla_cpu_workaround

xla_cpu_workaround()  # before any test starts JAX's CPU backend


@pytest.fixture(scope="module")
def shut_down_ray():
    """For a test file that starts a local Ray in this process (PB2, the Ray executor): stop it at
    the end of the file, so the files that follow on this worker start from no Ray."""
    yield
    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized():
        ray.shutdown()
