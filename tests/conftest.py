"""Test files that start a local Ray stop it when they end (process-wide settings: ../conftest.py)."""

import sys

import pytest


@pytest.fixture(scope="module")
def shut_down_ray():
    """For a test file that starts a local Ray in this process (PB2, the Ray executor): stop it at
    the end of the file, so the files that follow on this worker start from no Ray."""
    yield
    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized():
        ray.shutdown()
