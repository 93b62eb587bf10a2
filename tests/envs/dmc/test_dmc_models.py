"""Every dm_control domain on MJX builds dm_control's own model at its default context, leaf by leaf,
and declares its features with the reference's defaults and bounds: the quick tier's check of each
domain (in `make test-quick`), which compiles no MJX program; they step in test_dmc_mjx.py."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering, before MuJoCo loads

import jax  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

pytest.importorskip("dm_control")
pytest.importorskip("mujoco.mjx")

import contextrl as crl  # noqa: E402
from tests.envs.dmc.test_dmc_mjx import DOMAINS  # noqa: E402

pytestmark = pytest.mark.quick


@pytest.mark.parametrize("name", DOMAINS)
def test_default_context_builds_the_stock_model_with_the_references_features(name):
    env, host = crl.make(name, backend="mjx"), crl.make(name)
    built = jax.tree_util.tree_flatten_with_path(env.model(env.default_context()))[0]
    stock = jax.tree_util.tree_leaves(env.stock.model)
    assert len(built) == len(stock)
    for (path, ours), theirs in zip(built, stock, strict=True):
        np.testing.assert_allclose(ours, theirs, rtol=1e-6, err_msg=jax.tree_util.keystr(path))
    for feature_name, feature in env.context_space.features.items():
        reference = host.context_space.features[feature_name]
        assert (feature.default, feature.lower, feature.upper) == (
            reference.default,
            reference.lower,
            reference.upper,
        ), feature_name
