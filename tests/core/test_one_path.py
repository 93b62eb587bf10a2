"""One stepping path: the core ``ContextualEnv`` under ``jax.vmap``, the single gymnasium env and the
vector env give the same trajectories for the same seed and actions; importing changes nothing."""

from __future__ import annotations

import subprocess
import sys

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from gymnasium.utils import seeding

import contextrl as crl
from contextrl.core.contextual import GATHER_FROM, RESTART_SHARE
from contextrl.core.spaces import Discrete
from contextrl.gymnasium import gym_id
from contextrl.gymnasium.env import run_key_bits

# Every JAX family; of Brax, whose MJX programs take minutes to compile on a CPU, the cheapest task on
# brax's positional pipeline, which compiles in about half the time (its envs share one base, so the
# stepping path under test is the same for every task and pipeline; test_brax.py covers MJX's physics).
JAX_ENVS = [
    name
    for name in crl.registered()
    if not crl.spec(name).host
    and (crl.spec(name).family != "brax" or name == "BraxInvertedPendulum")
]
ENV_OPTIONS = {"BraxInvertedPendulum": {"backend": "positional"}}
STEPS = 40
MAX_STEPS = 12  # short episodes: several restarts (and context choices) per copy


def three_contexts(env):
    """The default context and two that move its first float feature towards its upper bound."""
    space = env.context_space
    name = next(n for n, f in space.features.items() if f.kind == "float")
    feature = space.features[name]
    default = float(feature.default)
    values = [default + share * (float(feature.upper) - default) for share in (0.0, 0.05, 0.1)]
    return [{name: value} for value in values]


def random_actions(env, rng, shape):
    if isinstance(env.action_space, Discrete):
        return rng.integers(0, env.action_space.n, shape).astype(np.int32)
    low, high = env.action_space.low, env.action_space.high
    return rng.uniform(low, high, (*shape, *env.action_space.shape)).astype(np.float32)


def core_run(env, contexts, selector, seed, copies, actions):
    """(obs, reward, terminated, truncated, context id) per step through ``jax.vmap`` by hand."""
    cenv = crl.with_contexts(env, contexts, selector)
    key = jax.random.wrap_key_data(jnp.asarray(run_key_bits(seeding.np_random(seed)[0])))
    reset = jax.jit(jax.vmap(cenv.reset, in_axes=(None, 0, None)), static_argnums=2)
    state, ts = reset(key, jnp.arange(copies), copies)
    step = jax.jit(jax.vmap(cenv.step))
    rows = [(ts.obs, None, None, None, state.context_id)]
    for action in actions:
        state, ts = step(state, jnp.asarray(action))
        rows.append((ts.obs, ts.reward, ts.terminated, ts.truncated, state.context_id))
    return [tuple(None if x is None else np.asarray(x) for x in row) for row in rows]


def vector_run(name, contexts, selector, seed, copies, actions):
    envs = gymnasium.make_vec(
        gym_id(name),
        num_envs=copies,
        contexts=contexts,
        context_selector=selector,
        max_steps=MAX_STEPS,
        **ENV_OPTIONS.get(name, {}),
    )
    obs, info = envs.reset(seed=seed)
    rows = [(obs, None, None, None, info["context_id"])]
    for action in actions:
        obs, reward, terminated, truncated, info = envs.step(action)
        rows.append((obs, reward, terminated, truncated, info["context_id"]))
    envs.close()
    return rows


def single_run(name, contexts, selector, seed, actions):
    env = gymnasium.make(
        gym_id(name),
        contexts=contexts,
        context_selector=selector,
        max_steps=MAX_STEPS,
        **ENV_OPTIONS.get(name, {}),
    )
    obs, info = env.reset(seed=seed)
    rows = [(obs[None], None, None, None, np.array([info["context_id"]]))]
    for action in actions[:, 0]:
        obs, reward, terminated, truncated, info = env.step(action)
        if terminated or truncated:  # gymnasium's single env restarts when asked
            obs, info = env.reset()
        rows.append(
            (obs[None], np.array([reward]), [terminated], [truncated], [info["context_id"]])
        )
    env.close()
    return rows


def assert_same(expected, actual, tolerance: float, where: str):
    """Equal ids and end flags; observations and rewards equal up to ``tolerance``.

    Separately compiled programs may round a sine differently in the last bit, and the single env's
    host path computes in float64 before rounding to float32.
    """
    for step, (want, got) in enumerate(zip(expected, actual, strict=True)):
        context = f"{where}, step {step}"
        np.testing.assert_allclose(got[0], want[0], rtol=tolerance, atol=tolerance, err_msg=context)
        if step:
            np.testing.assert_allclose(got[1], want[1], rtol=1e-5, atol=1e-5, err_msg=context)
            np.testing.assert_array_equal(got[2], want[2], err_msg=context)
            np.testing.assert_array_equal(got[3], want[3], err_msg=context)
        np.testing.assert_array_equal(got[4], want[4], err_msg=context)


@pytest.mark.parametrize("name", JAX_ENVS)
def test_vmap_single_and_vector_envs_follow_the_same_trajectories(name):
    env = crl.make(name, max_steps=MAX_STEPS, **ENV_OPTIONS.get(name, {}))
    contexts = three_contexts(env)
    rng = np.random.default_rng(0)
    copies = 3
    actions = random_actions(env, rng, (STEPS, copies))
    selector = "random"  # draws from the keys at every restart (round robin is tested below)
    by_hand = core_run(env, contexts, selector, 7, copies, actions)
    assert_same(by_hand, vector_run(name, contexts, selector, 7, copies, actions), 1e-6, name)
    alone = core_run(env, contexts, selector, 7, 1, actions[:, :1])
    assert_same(alone, single_run(name, contexts, selector, 7, actions), 1e-4, name)
    ends = sum(int(np.sum(row[2] | row[3])) for row in by_hand[1:])
    assert ends >= copies  # every copy restarted at least once on average
    assert len({int(i) for row in by_hand for i in row[4]}) == 3  # and every context ran


def test_copy_i_runs_global_episodes_i_plus_e_times_n():
    env = crl.make("CartPole", max_steps=3)
    contexts = crl.sample(env, {"length": crl.Uniform(0.3, 1.5)}, 8, jax.random.key(0))
    cenv = crl.with_contexts(env, contexts)
    state, ts = cenv.reset_copies(jax.random.key(1), 4)
    np.testing.assert_array_equal(ts.info["context_id"], [0, 1, 2, 3])
    step = jax.jit(cenv.step_copies)
    for _ in range(3):  # every episode ends at the 3-step limit
        state, ts = step(state, jnp.zeros(4, jnp.int32))
    np.testing.assert_array_equal(ts.info["context_id"], [0, 1, 2, 3])
    np.testing.assert_array_equal(state.context_id, [4, 5, 6, 7])
    np.testing.assert_array_equal(state.episode, [4, 5, 6, 7])
    # A custom selector learns which copy it serves: episode % N.
    by_copy = crl.with_contexts(env, contexts, lambda key, episode, n: (episode % 4) * 2)
    state, ts = by_copy.reset_copies(jax.random.key(1), 4)
    for _ in range(3):
        state, ts = jax.jit(by_copy.step_copies)(state, jnp.zeros(4, jnp.int32))
    np.testing.assert_array_equal(state.context_id, [0, 2, 4, 6])


def test_step_copies_equals_vmapped_step():
    """Few or many copies ending at once: the gathered restart and the full one agree with vmap."""
    env = crl.make("CartPole", max_steps=15).with_obs_context("all", noise=0.1)  # draws every step
    copies = GATHER_FROM
    cenv = crl.with_contexts(env, {"length": crl.Uniform(0.3, 1.5)})
    state, _ = cenv.reset_copies(jax.random.key(2), copies)
    batched, by_copy = jax.jit(cenv.step_copies), jax.jit(jax.vmap(cenv.step))
    one, other = state, state
    actions = np.random.default_rng(1).integers(0, 2, (40, copies)).astype(np.int32)
    ends = []
    for action in actions:
        one, ts_one = batched(one, action)
        other, ts_other = by_copy(other, action)
        ends.append(int(ts_one.done.sum()))
        for a, b in zip(
            jax.tree.leaves((one, ts_one)), jax.tree.leaves((other, ts_other)), strict=True
        ):
            if jnp.issubdtype(a.dtype, jnp.floating):  # two programs may round differently
                np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)
            else:
                np.testing.assert_array_equal(a, b)
    share = copies // RESTART_SHARE
    assert any(0 < n <= share for n in ends) and any(n > share for n in ends)  # both branches


def test_vector_reset_options_set_contexts_per_copy():
    contexts = {"short": {"length": 0.3}, "long": {"length": 1.5}}
    envs = gymnasium.make_vec("contextrl/CartPole-v0", num_envs=3, contexts=contexts)
    _, info = envs.reset(seed=0, options={"context_id": [None, "short", "long"]})
    assert info["context_id"].tolist() == ["short", "short", "long"]
    _, info = envs.reset(seed=0, options={"context": [{"length": 2.0}, None, None]})
    assert info["context_id"].tolist() == [-1, "long", "short"]
    np.testing.assert_allclose(info["context"]["length"], [2.0, 1.5, 0.3])
    _, info = envs.reset(options={"context": {"length": 0.7}})
    np.testing.assert_allclose(info["context"]["length"], [0.7] * 3)
    with pytest.raises(ValueError, match="lists 2 entries; give one per copy"):
        envs.reset(options={"context_id": ["short", "long"]})
    with pytest.raises(crl.ContextError, match="'middle' is not an id"):
        envs.reset(options={"context_id": "middle"})


def run_in_fresh_python(script: str) -> None:
    """Runs ``script`` in a new interpreter with a bare environment; fails the test if it fails."""
    environment = {"PATH": "/usr/bin:/bin", "MPLBACKEND": "svg", "PYTHONPATH": ":".join(sys.path)}
    result = subprocess.run(
        [sys.executable, "-c", script], env=environment, capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr[-2000:]


def test_importing_contextrl_changes_no_process_setting():
    script = (
        "import os, sys, matplotlib; before = dict(os.environ); backend = matplotlib.get_backend()\n"
        "import contextrl, contextrl.analysis, contextrl.experiments\n"
        "ours = {k for k in set(os.environ) ^ set(before) if k in ('XLA_FLAGS', 'MUJOCO_GL')}\n"
        "changed = {k for k in before if os.environ.get(k) != before[k]}\n"
        "assert not ours and not changed, (ours, changed)\n"
        "assert matplotlib.get_backend() == backend, matplotlib.get_backend()\n"
    )
    run_in_fresh_python(script)


def test_xla_flags_set_after_importing_contextrl_still_take_effect(tmp_path):
    """Importing contextrl starts no JAX backend, so the CLI's XLA:CPU workaround (set after the
    import) reaches XLA: here a flag set after the import makes XLA dump the next compiled program."""
    script = (
        "import os, jax, jax.numpy as jnp\n"
        "import contextrl, contextrl.cli, contextrl.experiments.runner, contextrl.envs.platformer\n"
        f"os.environ['XLA_FLAGS'] = '--xla_dump_to={tmp_path}'\n"
        "jax.jit(lambda x: 3 * x + 1)(jnp.ones(3)).block_until_ready()\n"
    )
    run_in_fresh_python(script)
    assert list(tmp_path.iterdir()), "XLA read its flags before contextrl's import returned"
