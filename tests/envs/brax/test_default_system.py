"""Every Brax task's system built from its default context is the stock one, leaf by leaf: the quick
tier's check of the family (in `make test-quick`), which compiles no MJX program; the tasks step in
test_brax.py, test_brax_large.py and test_reaching.py."""

import importlib.util

import jax
import numpy as np
import pytest

# Checked without importing brax: brax imports MuJoCo, which must see MUJOCO_GL=egl (set by the family).
if importlib.util.find_spec("brax") is None:
    pytest.skip("brax is not installed", allow_module_level=True)

import contextrl as crl  # noqa: E402

pytestmark = pytest.mark.quick


@pytest.mark.parametrize("env_id", [i for i in crl.registered() if crl.spec(i).family == "brax"])
def test_brax_default_context_builds_the_stock_system(env_id):
    env = crl.make(env_id)
    built = jax.tree_util.tree_flatten_with_path(env.system(env.default_context()))[0]
    stock = jax.tree_util.tree_leaves(env.stock_system)
    assert len(built) == len(stock)
    for (path, ours), theirs in zip(built, stock, strict=True):
        np.testing.assert_allclose(ours, theirs, rtol=1e-6, err_msg=jax.tree_util.keystr(path))
