"""The Brax family: every task matches brax step by step at the default context and every declared
feature changes the trajectory (the three largest tasks in test_brax_large.py), each copy of one
vmapped batch runs its own physics (the CARL failure cannot happen), the systems built from contexts
are brax's and MuJoCo's, the goal variant and Pusher's reset follow the context. The programs are
described in tests/helpers/brax_rollouts.py; the checker, the gymnasium face and learning: test_brax_agents.py.
"""

import copy
import dataclasses
import importlib.util

import jax
import jax.numpy as jnp
import numpy as np
import pytest

# Checked without importing brax: brax imports MuJoCo, which must see MUJOCO_GL=egl (set by the family).
if importlib.util.find_spec("brax") is None:
    pytest.skip("brax is not installed", allow_module_level=True)

import contextrl as crl  # noqa: E402
from contextrl.context.features import ContextError  # noqa: E402
from contextrl.envs import brax as family  # noqa: E402
from tests.helpers.brax_rollouts import (  # noqa: E402
    CONFIGURATIONS,
    LARGE,
    NAMES,
    assert_every_feature_acts,
    assert_finite_while_running,
    assert_matches_brax,
    brax_own,
    copy_trajectory,
    differs,
    moved_value,
    rollouts,
)

# In make test: Ant (contacts, and CARL's failure below shares its program), Hopper (the goal test
# shares its program) and InvertedPendulum; the other tasks run the same code in `make test-slow`.
EVERY_EDIT = ("Ant", "Hopper", "InvertedPendulum")


@pytest.mark.parametrize(
    "name",
    [
        name if name in EVERY_EDIT else pytest.param(name, marks=pytest.mark.slow)
        for name in NAMES
        if name not in LARGE
    ],
)
def test_default_context_matches_brax_and_every_feature_acts(name):
    rows, ours, theirs = rollouts(name, **CONFIGURATIONS[name])
    assert_matches_brax(ours, theirs)
    assert_finite_while_running(ours)
    assert_every_feature_acts(rows, ours)
    if not CONFIGURATIONS[name].get("goal"):
        np.testing.assert_array_equal(ours["reward"], ours["brax_reward"])


def test_carl_failure_cannot_happen_gravity_and_torso_mass_act_in_one_batch():
    """CARL's Brax contexts gave identical trajectories for gravity 9.8 vs 1 and torso mass ×10."""
    rows, ours, _ = rollouts("Ant")
    index = {label: i for i, (label, _) in enumerate(rows)}
    assert differs(ours, index["gravity 9.8"], index["gravity 1"])
    assert differs(ours, index["default"], index["torso mass x10"])
    # Lower gravity: the ant falls more slowly (z of the torso is the first observation).
    low, normal = ours["obs"][:, index["gravity 1"], 0], ours["obs"][:, index["gravity 9.8"], 0]
    assert low[-1] > normal[-1]


def test_spring_pipeline_matches_brax_and_models_elasticity_and_angular_damping():
    """Spring and positional drift from brax's own program (HalfCheetah: 1e-4 by step 10, 1e-2 by
    step 20, 4e-2 by step 30), and this is float32 rounding amplified by the contacts, not another
    system: our default system is brax's leaf by leaf (``test_default_system_is_brax_system``); brax's
    own environment run with its system passed at run time, instead of folded into the program as
    constants, drifts from itself exactly as far (ours matched that one bit for bit over 30 steps);
    moving brax's gravity by one ulp drifts as far (4e-1 by step 30); in float64 the two brax programs
    agree to 1e-11 at step 10 and 1e-6 at step 30. MJX drifts as much beyond ten steps (brax against
    itself: 8e-2 by step 20); only which program happens to fold like brax's differs."""
    rows, ours, theirs = rollouts("HalfCheetah", backend="spring")
    assert {"elasticity", "ang_damping"} <= {label for label, _ in rows}
    assert_matches_brax(ours, theirs, tolerance=1e-3)
    assert_every_feature_acts(rows, ours)


def test_goal_variant_rewards_progress_toward_the_target_and_ends_there():
    """Hopper's program (shared with its parity test) runs the goal variant."""
    rows, ours, theirs = rollouts("Hopper", **CONFIGURATIONS["Hopper"])
    assert {"target_distance", "target_direction", "target_radius"} <= {label for label, _ in rows}
    index = {label: i for i, (label, _) in enumerate(rows)}
    # The reward is the step's decrease of the torso's distance to the target (100 m east), floored at
    # 0 as CARL's: a step away from the target earns 0, not a penalty.
    default = copy_trajectory(ours, index["default"])
    distance = np.linalg.norm(default["torso"] - np.array([100.0, 0.0]), axis=-1)
    progress = distance[:-1] - distance[1:]
    np.testing.assert_allclose(default["reward"], np.maximum(0.0, progress), atol=1e-5)
    west = copy_trajectory(ours, index["target_direction"])  # the target 100 m west instead
    west_progress = -np.diff(np.linalg.norm(west["torso"] - np.array([-100.0, 0.0]), axis=-1))
    assert np.any(progress < -1e-4) or np.any(west_progress < -1e-4)  # some step moved away
    np.testing.assert_allclose(west["reward"], np.maximum(0.0, west_progress), atol=1e-5)
    assert not np.allclose(default["reward"], theirs["reward"])
    # A radius wider than the target's distance: reached at the first step, the episode ends.
    assert ours["terminated"][0, index["target_radius"]]
    # Far from the target, the episode ends only when brax's hopper falls.
    np.testing.assert_array_equal(default["terminated"], theirs["terminated"])


def test_pusher_starts_the_object_clear_of_the_contexts_goal():
    """brax's Pusher keeps the object's start 0.17 m from the stock goal; ours from the context's goal.
    With the goal moved into the middle of the region the start is drawn from, each of 64 starts keeps
    the clearance (brax's rule, measured from the stock goal, leaves some on the goal). The reset is the
    same on every pipeline; positional's compiles fastest."""
    env = family.Pusher(backend="positional")
    goal = np.array([0.45, -0.2])
    context = env.context(goal_position_x=goal[0], goal_position_y=goal[1])
    keys = jax.random.split(jax.random.key(0), 64)
    states = jax.jit(jax.vmap(env.init, in_axes=(0, None)))(keys, context)
    link = env.stock_system.link_names.index("object")
    distance = np.linalg.norm(np.asarray(states.pipeline_state.x.pos[:, link, :2]) - goal, axis=-1)
    assert distance.min() >= 0.17 - 1e-5, distance.min()


def test_registered_with_carl_aliases_and_validated():
    reaching = [cls.__name__ for cls in family.REACHING_ENVIRONMENTS]
    assert crl.registered("brax") == sorted([f"Brax{n}" for n in NAMES] + reaching)
    assert crl.spec("CARLBraxAnt").id == "BraxAnt"
    env = crl.make("CARLBraxPusher")
    assert env.default_context().gravity == 0.0  # the stock pusher has no gravity
    with pytest.raises(ContextError, match=r"mass_torso.*bounds"):
        crl.make("BraxAnt").context(mass_torso=100.0)
    with pytest.raises(ValueError, match="backend must be one of"):
        family.Ant(backend="warp")
    with pytest.raises(ValueError, match="no goal variant"):
        family.Reacher(goal=True)
    assert "elasticity" not in env.context_space.names  # MJX does not model restitution
    assert "viscosity" not in family.Ant().context_space.names
    assert "viscosity" in family.Ant(fluid=True).context_space.names
    with pytest.raises(ValueError, match="fluid=True needs the mjx backend"):
        family.Ant(backend="generalized", fluid=True)


def test_context_types_are_shared_per_configuration():
    assert family.Ant().context_type is family.Ant(max_steps=5).context_type
    assert family.Ant(goal=True).context_type is not family.Ant().context_type


@pytest.mark.parametrize(
    "name, backend",
    [(name, "mjx") for name in NAMES]
    + [("HalfCheetah", backend) for backend in family.BACKENDS if backend != "mjx"],
)
def test_default_system_is_brax_system(name, backend):
    """At the default context the system built from the context is brax's, leaf by leaf and value for
    value (an integer gear, which a strength scales, becomes a float of the same value)."""
    env = getattr(family, name)(backend=backend)
    built = jax.tree_util.tree_flatten_with_path(env.system(env.default_context()))[0]
    stock = jax.tree_util.tree_flatten_with_path(brax_own(env.brax_name, backend).sys)[0]
    assert [jax.tree_util.keystr(p) for p, _ in built] == [
        jax.tree_util.keystr(p) for p, _ in stock
    ]
    for (path, ours), (_, theirs) in zip(built, stock, strict=True):
        ours, theirs = np.asarray(ours), np.asarray(theirs)
        where = f"{name} ({backend}): {jax.tree_util.keystr(path)}"
        np.testing.assert_array_equal(ours, theirs, err_msg=where)
        same_kind = ours.dtype == theirs.dtype or np.issubdtype(theirs.dtype, np.integer)
        assert same_kind, f"{where}: {ours.dtype} vs {theirs.dtype}"


@pytest.mark.parametrize("name", NAMES)
def test_mass_derived_constants_are_mujocos_for_the_contexts_masses(name):
    """MuJoCo derives each body's and joint's inverse weight (how soft its contacts and joint limits
    are) and the subtree masses from the masses when it loads a model (``mj_setConst``). With every
    mass feature moved, our system holds what ``mj_setConst`` computes for those masses (to float32
    rounding), on MJX and in the generalized pipeline's copies, and these differ from the stock ones."""
    import mujoco

    env = getattr(family, name)()
    system = env.system(
        env.context(**{n: moved_value(env.context_space.features[n]) for n in env.masses})
    )
    model = copy.deepcopy(env.stock_system.mj_model)
    model.body_mass[:], model.body_inertia[:] = system.body_mass, system.body_inertia
    mujoco.mj_setConst(model, mujoco.MjData(model))
    for field in ("body_invweight0", "dof_invweight0", "body_subtreemass"):
        np.testing.assert_allclose(
            getattr(system, field), getattr(model, field), rtol=1e-4, err_msg=field
        )
    assert not np.allclose(system.body_invweight0, env.stock_system.body_invweight0)
    generalized = getattr(family, name)(backend="generalized")
    system = generalized.system(
        generalized.context(**{n: moved_value(env.context_space.features[n]) for n in env.masses})
    )
    np.testing.assert_allclose(system.link.invweight, model.body_invweight0[1:, 0], rtol=1e-4)
    np.testing.assert_allclose(system.dof.invweight, model.dof_invweight0, rtol=1e-4)


@pytest.mark.parametrize("backend", ["spring", "positional"])
@pytest.mark.parametrize("name", NAMES)
def test_masses_scale_what_the_maximal_coordinate_pipelines_use(name, backend):
    """brax's spring and positional pipelines use mass**(1 - s) and inertia**(1 - s_i), with s and s_i
    the model's spring scales. A mass feature moved to r × its default scales these effective values
    of its link, and only its link's, by r (where the exponent is above 0: the inertias of most tasks
    are fixed at 1); a task whose exponents are both 0 (Ant, Hopper, Pusher), where no mass can act,
    declares no mass feature on these pipelines."""
    env = getattr(family, name)(backend=backend)
    stock = env.stock_system
    exponents = 1 - float(stock.spring_mass_scale), 1 - float(stock.spring_inertia_scale)

    def effective(system):
        inertia = np.diagonal(np.asarray(system.link.inertia.i), axis1=1, axis2=2)
        return np.asarray(system.link.inertia.mass) ** exponents[0], inertia ** exponents[1]

    declared = [n for n in env.context_space.names if n in env.masses]
    if exponents == (0.0, 0.0):
        assert declared == [] and name in {"Ant", "Hopper", "Pusher"}
        return
    assert declared == list(env.masses)
    for feature_name, (link, default) in env.masses.items():
        value = moved_value(env.context_space.features[feature_name])
        expected = np.ones(len(stock.link_names))
        expected[stock.link_names.index(link)] = value / default
        moved, original = (
            effective(env.system(env.context(**{feature_name: value}))),
            effective(stock),
        )
        np.testing.assert_allclose(
            moved[0] / original[0], expected ** (exponents[0] > 0), rtol=1e-5
        )
        np.testing.assert_allclose(
            moved[1] / original[1], expected[:, None] ** (exponents[1] > 0) * np.ones(3), rtol=1e-4
        )


def test_dataclass_replace_keeps_the_loaded_model():
    env = family.Hopper()
    shorter = dataclasses.replace(env, max_steps=10)
    assert shorter.stock_system is env.stock_system and shorter.max_steps == 10
    assert jnp.shape(shorter.action_space.low) == (3,)
