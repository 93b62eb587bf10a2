"""Brax's own rollout beside ours, shared by the Brax test files (test_brax*.py).

MJX compiles slowly on CPU (compiling, not stepping, is nearly all of these files' time), so each
configuration is compiled once (``rollouts`` is cached per process) and runs few steps with few copies:
one program per task holds brax's own rollout and ours over a batch of contexts (the default one, one
per feature moved off its default, and CARL's failure cases). Hopper's program is its goal variant,
which also carries brax's own reward in its state, so one program shows both parity and the goal
reward. Import this module only after checking that brax is installed.
"""

import functools

import jax
import numpy as np

from contextrl.envs import brax as family
from contextrl.testing import probe_values

STEPS = 30  # long enough for every walker's feet to reach the ground
# Tasks without a walker's fall need fewer (Pusher's MJX step is by far the slowest to run on CPU).
FEWER_STEPS = {"Pusher": 8, "Reacher": 8, "InvertedPendulum": 8, "InvertedDoublePendulum": 8}
PARITY_STEPS = 8  # contacts amplify float rounding; brax's own rollout is compared over these
NAMES = [cls.__name__ for cls in family.ENVIRONMENTS]
LARGE = ["Humanoid", "HumanoidStandup", "Pusher"]  # the slowest programs: test_brax_large.py
# The configuration each task's parity program runs: Hopper's goal variant keeps brax's physics and
# brax's reward (in its state), so the goal test shares Hopper's program.
CONFIGURATIONS = {name: {} for name in NAMES} | {"Hopper": {"goal": True}}


def moved_value(feature):
    """A value off the default: a different compass code, else halfway to the upper bound (or the
    lower one where the default sits at the top)."""
    if feature.kind == "categorical":
        return probe_values(feature)[0]
    if feature.default < feature.upper:
        return (feature.default + feature.upper) / 2
    return (feature.default + feature.lower) / 2


def batch_rows(env) -> list[tuple[str, dict]]:
    """(label, feature values) per copy: the default, each feature moved alone, CARL's cases.

    The goal variant's target is moved within reach (its lower bound, inside the radius): a planar
    walker's progress, floored at 0, is the same toward any target ahead, so a farther one would show
    only in float rounding; a reachable one ends the episode at once."""
    rows = [("default", {})]
    for name, feature in env.context_space.features.items():
        value = feature.lower if name == "target_distance" else moved_value(feature)
        rows.append((name, {name: value}))
    if "gravity" in env.context_space.names:
        rows += [("gravity 9.8", {"gravity": 9.8}), ("gravity 1", {"gravity": 1.0})]
    if "mass_torso" in env.context_space.names:
        torso = env.context_space.features["mass_torso"].default
        rows.append(("torso mass x10", {"mass_torso": 10 * torso}))
    return rows


@functools.cache
def brax_own(brax_name: str, backend: str):
    """brax's own environment, loaded once per test session."""
    from brax import envs as brax_envs

    return brax_envs.get_environment(brax_name, backend=backend)


@functools.cache
def rollouts(name: str, backend: str = "mjx", goal: bool = False, fluid: bool = False):
    """brax's own rollout and ours over a batch of contexts, from one key and one action sequence.

    Returns (rows, ours, theirs): ``ours`` maps "obs", "reward", "terminated" to arrays of shape
    (steps + 1 for obs | steps, copies, ...), "brax_reward" to brax's reward kept in our state and
    "torso" to the (x, y) of the first link; ``theirs`` has the first three for brax's unbatched env.
    """
    env = getattr(family, name)(backend=backend, goal=goal, fluid=fluid)
    stock = brax_own(env.brax_name, backend)
    rows = batch_rows(env)
    contexts = env.context_space.stack([env.context(**values) for _, values in rows])
    key, action_key = jax.random.split(jax.random.key(7))
    steps = FEWER_STEPS.get(name, STEPS)
    actions = jax.vmap(env.action_space.sample)(jax.random.split(action_key, steps))

    def run(key, contexts, actions):
        ours = jax.vmap(env.init, in_axes=(None, 0))(key, contexts)
        theirs = stock.reset(key)
        transition = jax.vmap(env.transition, in_axes=(None, 0, None, 0))

        def body(carry, action):
            ours, theirs = carry
            ours, reward, terminated = transition(key, ours, action, contexts)
            theirs = stock.step(theirs, action)
            return (ours, theirs), (
                jax.vmap(env.observe)(ours, contexts),
                reward,
                terminated,
                ours.reward,
                ours.pipeline_state.x.pos[:, 0, :2],
                theirs.obs,
                theirs.reward,
                theirs.done > 0.5,
            )

        first = (
            jax.vmap(env.observe)(ours, contexts),
            theirs.obs,
            ours.pipeline_state.x.pos[:, 0, :2],
        )
        _, trajectory = jax.lax.scan(body, (ours, theirs), actions)
        return first, trajectory

    (first_ours, first_theirs, first_torso), trajectory = jax.jit(run)(key, contexts, actions)
    obs, reward, terminated, brax_reward, torso, their_obs, their_reward, their_done = map(
        np.asarray, trajectory
    )
    ours = {
        "obs": np.concatenate([np.asarray(first_ours)[None], obs]),
        "reward": reward,
        "terminated": terminated,
        "brax_reward": brax_reward,
        "torso": np.concatenate([np.asarray(first_torso)[None], torso]),
    }
    theirs = {
        "obs": np.concatenate([np.asarray(first_theirs)[None], their_obs]),
        "reward": their_reward,
        "terminated": their_done,
    }
    return rows, ours, theirs


def copy_trajectory(ours, index):
    return {k: v[:, index] for k, v in ours.items()}


def assert_matches_brax(ours, theirs, tolerance=1e-4):
    """Copy 0 (the default context) is brax's rollout, to float32 rounding: our program computes the
    system's values at run time where brax's folds them as constants, and one ulp of difference grows
    along a trajectory (see the spring test); brax's reward is the one kept in our state (the goal
    variant returns its own)."""
    default = copy_trajectory(ours, 0)
    pairs = {
        "obs": (default["obs"][: PARITY_STEPS + 1], theirs["obs"][: PARITY_STEPS + 1]),
        "reward": (default["brax_reward"][:PARITY_STEPS], theirs["reward"][:PARITY_STEPS]),
    }
    for key, (mine, brax) in pairs.items():
        np.testing.assert_allclose(mine, brax, rtol=tolerance, atol=tolerance, err_msg=key)
    np.testing.assert_array_equal(
        default["terminated"][:PARITY_STEPS], theirs["terminated"][:PARITY_STEPS]
    )


def differs(ours, a, b) -> bool:
    return any(not np.array_equal(v[:, a], v[:, b], equal_nan=True) for v in ours.values())


def assert_finite_while_running(ours):
    """Every copy stays finite until its episode ends (the rollout steps on past an end, where a
    fallen humanoid under random actions may diverge; a real episode restarts there)."""
    ended = np.cumsum(ours["terminated"], axis=0) > 0  # [t]: the episode ended at step t or before
    stepping = np.concatenate(
        [np.ones_like(ended[:1]), ~ended[:-1]]
    )  # [t]: step t is taken mid-episode
    after = np.concatenate([np.ones_like(ended[:1]), stepping])  # the first obs, then each step's
    assert np.all(np.isfinite(ours["reward"][stepping])), "non-finite reward mid-episode"
    assert np.all(np.isfinite(ours["obs"][after])), "non-finite observation mid-episode"


def assert_every_feature_acts(rows, ours):
    silent = [label for i, (label, _) in enumerate(rows) if i > 0 and not differs(ours, 0, i)]
    assert not silent, f"features that left the trajectory unchanged: {silent}"
