"""The dm_control family: stock parity, every feature acting on the model, seeding, isolation, errors."""

from __future__ import annotations

import dataclasses
import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering, before MuJoCo loads

import numpy as np  # noqa: E402
import pytest  # noqa: E402

pytest.importorskip("dm_control")

import mujoco  # noqa: E402
from dm_control import suite  # noqa: E402

from contextrl import ContextError  # noqa: E402
from contextrl.envs import dmc  # noqa: E402

STEPS = 25
ENVS = {cls.__name__: cls for cls in dmc.ENVIRONMENTS}

# A changed value per feature (in bounds, valid with every other default).
CHANGED = {
    "gravity": lambda default: 4.0 if default else 9.81,
    "friction_tangential": lambda default: 0.3,
    "timestep": lambda default: default / 2,
    "joint_damping": lambda default: 3.0,
    "joint_stiffness": lambda default: 3.0,
    "actuator_strength": lambda default: 2.0,
    "geom_density": lambda default: 2.0,
    "density": lambda default: 2000.0 if default else 1000.0,
    "viscosity": lambda default: 2.0,
    "wind_x": lambda default: 0.25,
    "wind_y": lambda default: 0.25,
    "wind_z": lambda default: 0.25,
    "limb_length_0": lambda default: 0.19,
    "limb_length_1": lambda default: 0.18,
    "spinner_length": lambda default: 0.3,
    "spinner_radius": lambda default: 0.03,
    "mass": lambda default: 1.0,
    "starting_x": lambda default: 0.1,
    "starting_y": lambda default: -0.1,
    "start_spread": lambda default: 0.5,
    "target_x": lambda default: 0.2,
    "target_y": lambda default: -0.2,
    "area_size": lambda default: 1.0,
}


def changed_value(env, name: str) -> float:
    return float(np.float32(CHANGED[name](env.context_space.features[name].default)))


def shared_values(env, name: str) -> dict:
    """Wind acts only through a medium: where the stock has none, both runs get one."""
    if name.startswith("wind") and env.context_space.features["density"].default == 0:
        return {"density": 1000.0}
    if name in ("target_x", "target_y"):  # start where the moved target is: the reward must change
        start = {"target_x": "starting_x", "target_y": "starting_y"}[name]
        return {start: changed_value(env, name), "start_spread": 0.0}
    return {}


def flat(observation) -> np.ndarray:
    return np.concatenate([np.asarray(v, np.float32).ravel() for v in observation.values()])


def rollout(env, context, seed: int = 1, steps: int = STEPS) -> np.ndarray:
    """Observations and rewards of one seeded episode under a fixed action sequence."""
    actions = np.random.default_rng(100).uniform(-1, 1, (steps, *env.action_space.shape))
    rows = [np.append(env.reset_physics(context, np.random.default_rng(seed)), 0.0)]
    for action in actions:
        obs, reward, _ = env.step_physics(action)
        rows.append(np.append(obs, reward))
    return np.array(rows)


def stock_env(cls, seed: int | None = None, task: str | None = None):
    return suite.load(cls.domain, task or cls.default_task, task_kwargs={"random": seed})


def model_arrays(model) -> dict[str, np.ndarray]:
    """Every numeric array of an MjModel, plus the physics options."""
    arrays = {}
    for name in dir(model):
        if name.startswith("_"):
            continue
        value = getattr(model, name, None)
        if isinstance(value, np.ndarray) and value.dtype.kind in "fiub":
            arrays[name] = value.copy()
    for name in ("timestep", "gravity", "wind", "density", "viscosity", "disableflags"):
        arrays[f"opt.{name}"] = np.array(getattr(model.opt, name))
    for name in ("meaninertia", "meanmass", "meansize", "extent", "center"):
        arrays[f"stat.{name}"] = np.array(getattr(model.stat, name))
    return arrays


@pytest.fixture(scope="module")
def built():
    """One environment and one stock model (as its task runs it) per class, shared by the tests:
    every reset rewrites the model from the stock values, which is part of what is tested."""
    pairs = {}
    for name, cls in ENVS.items():
        stock = stock_env(cls, seed=0)
        stock.reset()
        pairs[name] = (cls(), stock.physics.model)
    return pairs


def all_changed(env) -> dict:
    return {name: changed_value(env, name) for name in env.context_space.names}


# ---- parity with stock dm_control ----------------------------------------------------------------


@pytest.mark.parametrize("name", list(ENVS))
def test_default_context_is_stock_dm_control_step_by_step(built, name):
    env, _ = built[name]
    cls = ENVS[name]
    env.reset_physics(env.context(**all_changed(env)), np.random.default_rng(1))  # then switch back
    stock = stock_env(cls, seed=dmc.task_seed(np.random.default_rng(5)))
    obs = env.reset_physics(env.default_context(), np.random.default_rng(5))
    np.testing.assert_array_equal(obs, flat(stock.reset().observation))
    for action in np.random.default_rng(0).uniform(-1, 1, (40, *env.action_space.shape)):
        obs, reward, terminated = env.step_physics(action)
        expected = stock.step(action)
        np.testing.assert_array_equal(obs, flat(expected.observation))
        assert reward == expected.reward
        assert not terminated


OTHER_TASKS = [
    (cls, task)
    for cls in dmc.ENVIRONMENTS
    for task in suite.TASKS_BY_DOMAIN[cls.domain]
    if task != cls.default_task
]


@pytest.mark.parametrize(
    "cls, task", OTHER_TASKS, ids=[f"{c.__name__}-{t}" for c, t in OTHER_TASKS]
)
def test_every_other_task_matches_stock(cls, task):
    env = cls(task)
    stock = stock_env(cls, seed=dmc.task_seed(np.random.default_rng(2)), task=task)
    np.testing.assert_array_equal(
        env.reset_physics(env.default_context(), np.random.default_rng(2)),
        flat(stock.reset().observation),
    )
    for action in np.random.default_rng(0).uniform(-1, 1, (20, *env.action_space.shape)):
        obs, reward, _ = env.step_physics(action)
        expected = stock.step(action)
        np.testing.assert_array_equal(obs, flat(expected.observation))
        assert reward == expected.reward


def test_switching_back_restores_every_model_value(built):
    for name in ENVS:
        env, _ = built[name]
        fresh = ENVS[name]()
        fresh.reset_physics(fresh.default_context(), np.random.default_rng(0))
        env.reset_physics(env.context(**all_changed(env)), np.random.default_rng(0))
        env.reset_physics(env.default_context(), np.random.default_rng(0))
        before, after = model_arrays(fresh.physics.model), model_arrays(env.physics.model)
        for field, value in before.items():
            np.testing.assert_array_equal(after[field], value, err_msg=f"{name}: {field}")


# ---- every feature acts, on the model and on the trajectory ---------------------------------------


def check_model(env, stock, name: str, value: float) -> None:
    """The model value the feature names changed by the declared amount."""
    model, opt = env.physics.model, env.physics.model.opt
    if name == "gravity":
        np.testing.assert_allclose(opt.gravity, [0.0, 0.0, -value], rtol=1e-6)
        assert not opt.disableflags & mujoco.mjtDisableBit.mjDSBL_GRAVITY
    elif name == "friction_tangential":
        np.testing.assert_array_equal(model.geom_friction[:, 0], stock.geom_friction[:, 0] * value)
        np.testing.assert_array_equal(model.geom_friction[:, 1:], stock.geom_friction[:, 1:])
    elif name == "timestep":
        assert opt.timestep == value
        assert env.n_sub_steps == round(env.control_timestep / value)
    elif name == "joint_damping":
        np.testing.assert_array_equal(model.dof_damping, stock.dof_damping * value)
        assert np.any(model.dof_damping != stock.dof_damping)
    elif name == "joint_stiffness":
        np.testing.assert_array_equal(model.jnt_stiffness, stock.jnt_stiffness * value)
        assert np.any(model.jnt_stiffness != stock.jnt_stiffness)
    elif name == "actuator_strength":
        np.testing.assert_array_equal(
            model.actuator_gainprm[:, 0], stock.actuator_gainprm[:, 0] * value
        )
        np.testing.assert_array_equal(
            model.actuator_biasprm[:, :3], stock.actuator_biasprm[:, :3] * value
        )
        np.testing.assert_array_equal(model.actuator_gear, stock.actuator_gear)
    elif name == "geom_density":
        np.testing.assert_allclose(model.body_mass, stock.body_mass * value, rtol=1e-12)
        np.testing.assert_allclose(model.body_inertia, stock.body_inertia * value, rtol=1e-12)
        np.testing.assert_allclose(
            model.body_subtreemass, stock.body_subtreemass * value, rtol=1e-12
        )
    elif name in ("density", "viscosity"):
        assert getattr(opt, name) == value
    elif name.startswith("wind"):
        axis = "xyz".index(name[-1])
        assert opt.wind[axis] == value
        assert np.count_nonzero(opt.wind) == 1
    elif name == "limb_length_0":
        assert model.geom("proximal").size[1] == pytest.approx(value / 2)
        assert model.body("distal").pos[2] == pytest.approx(-(value + 0.01))
    elif name == "limb_length_1":
        assert model.geom("distal").size[1] == pytest.approx(value / 2)
    elif name == "spinner_length":
        for cap in ("cap1", "cap2"):
            assert model.geom(cap).size[1] == pytest.approx(value / 2)
    elif name == "spinner_radius":
        for cap in ("cap1", "cap2"):
            assert model.geom(cap).size[0] == pytest.approx(value)
    elif name == "mass":
        assert model.body("pointmass").mass[0] == value
    elif name in ("target_x", "target_y"):
        assert model.geom("target").pos["xy".index(name[-1])] == value
    elif name == "area_size":
        np.testing.assert_allclose(model.jnt_range, stock.jnt_range * value / 0.6)
        assert model.geom("wall_neg_x").pos[0] == pytest.approx(value / 2)
    elif name in ("starting_x", "starting_y", "start_spread"):
        pass  # start features change the start state, checked below
    else:  # pragma: no cover - a new feature needs a check here
        raise AssertionError(f"no model check for {name}")


FEATURES = [(env_name, f) for env_name, cls in ENVS.items() for f in cls.context_type.space.names]


@pytest.mark.parametrize("env_name, name", FEATURES)
def test_every_feature_changes_the_model_and_the_trajectory(built, env_name, name):
    env, stock = built[env_name]
    shared = shared_values(env, name)
    value = changed_value(env, name)
    reference = rollout(env, env.context(**shared))
    changed = rollout(env, env.context(**shared, **{name: value}))
    check_model(env, stock, name, value)
    assert np.all(np.isfinite(changed))
    assert not np.allclose(changed, reference), f"{env_name}: {name}={value} changed nothing"


# Room for features whose extremes need another feature's help to be valid (a long spinner for short
# limbs, a large arena for a far start or target).
ROOM = {
    "DmcFinger": {"spinner_length": 0.4, "spinner_radius": 0.05},
    "DmcPointMass": {"area_size": 2.0},
}


def test_every_feature_at_both_bounds_runs_without_error(built):
    for env_name, (env, _) in built.items():
        actions = np.random.default_rng(1).uniform(
            env.action_space.low, env.action_space.high, (30, *env.action_space.shape)
        )
        for name, spec in env.context_space.features.items():
            room = {k: v for k, v in ROOM.get(env_name, {}).items() if k != name}
            for value in spec.bounds:
                env.reset_physics(env.context(**room, **{name: value}), np.random.default_rng(0))
                for action in actions:
                    obs, reward, terminated = env.step_physics(action)
                    assert np.all(np.isfinite(obs)) and np.isfinite(reward)
                    if terminated:  # only the largest time steps let the simulation diverge
                        assert name == "timestep" and value >= 0.04, (env_name, name, value)
                        break


def test_finger_gravity_is_off_by_default_like_stock_and_acts_when_set(built):
    env, _ = built["DmcFinger"]
    env.reset_physics(env.default_context(), np.random.default_rng(0))
    assert env.physics.model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_GRAVITY
    # The finger starts at rest; with zero controls only gravity can lower its centre of mass.
    drops = []
    for gravity in (0.0, 9.81):
        env.reset_physics(env.context(gravity=gravity), np.random.default_rng(0))
        start = env.physics.named.data.subtree_com["proximal", "z"]
        for _ in range(20):
            env.step_physics(np.zeros(2))
        drops.append(start - env.physics.named.data.subtree_com["proximal", "z"])
    assert drops[0] == 0.0
    assert drops[1] > 0.005


def test_point_mass_start_features_place_the_ball(built):
    env, _ = built["DmcPointMass"]
    obs = env.reset_physics(
        env.context(starting_x=0.15, starting_y=-0.05, start_spread=0.0), np.random.default_rng(3)
    )
    np.testing.assert_allclose(obs[:2], [0.15, -0.05], atol=1e-6)
    stock_start = env.reset_physics(env.default_context(), np.random.default_rng(3))[:2]
    half = env.reset_physics(env.context(start_spread=0.5), np.random.default_rng(3))[:2]
    np.testing.assert_allclose(half, 0.5 * stock_start, atol=1e-6)


def test_timestep_anywhere_in_bounds_keeps_the_control_step(built):
    for name in ENVS:
        env, _ = built[name]
        low, high = env.context_space.features["timestep"].bounds
        for timestep in (low, 0.003, high):
            env.reset_physics(env.context(timestep=timestep), np.random.default_rng(0))
            ts = env.physics.model.opt.timestep
            expected = max(1, round(env.control_timestep / ts))
            start = env.physics.data.time
            _, _, terminated = env.step_physics(np.zeros(env.action_space.shape))
            assert env.n_sub_steps == expected
            if not terminated:  # a diverged simulation ends the episode instead of raising
                assert env.physics.data.time - start == pytest.approx(expected * ts)


# ---- seeding and isolation --------------------------------------------------------------------------


def test_same_seed_same_trajectory_other_seed_other_start(built):
    env, _ = built["DmcWalker"]
    context = env.context(viscosity=0.5)
    np.testing.assert_array_equal(rollout(env, context, seed=7), rollout(env, context, seed=7))
    assert not np.allclose(rollout(env, context, seed=7)[0], rollout(env, context, seed=8)[0])


def test_two_environments_in_one_process_do_not_affect_each_other(built):
    alone, _ = built["DmcWalker"]
    expected = rollout(alone, alone.default_context(), seed=4)
    first, second = dmc.DmcWalker(), dmc.DmcWalker()
    second.reset_physics(
        second.context(gravity=2.0, viscosity=3.0, geom_density=3.0), np.random.default_rng(1)
    )
    rows = [np.append(first.reset_physics(first.default_context(), np.random.default_rng(4)), 0.0)]
    actions = np.random.default_rng(100).uniform(-1, 1, (STEPS, 6))
    for action in actions:
        second.step_physics(-action)
        obs, reward, _ = first.step_physics(action)
        rows.append(np.append(obs, reward))
    np.testing.assert_array_equal(np.array(rows), expected)


# ---- bad input ------------------------------------------------------------------------------------


def test_bad_input_is_refused_clearly_and_leaves_the_environment_usable(built):
    env, _ = built["DmcFinger"]
    expected = rollout(env, env.default_context(), seed=2)
    with pytest.raises(ContextError, match="cannot reach the spinner"):
        env.reset_physics(
            env.context(limb_length_0=0.01, limb_length_1=0.01), np.random.default_rng(0)
        )
    with pytest.raises(ContextError, match=r"gravity.*outside its bounds"):
        env.context(gravity=-1.0)
    # a feature of the original environment that cannot act here: refused with the reason
    with pytest.raises(
        ContextError, match="'joint_stiffness' is left out of DmcWalkerContext: every"
    ):
        dmc.DmcWalker.context_type.space.make(joint_stiffness=2.0)
    with pytest.raises(ContextError, match="one value per episode"):
        env.reset_physics(
            env.context_space.stack([env.default_context()] * 2), np.random.default_rng(0)
        )
    with pytest.raises(ContextError, match="expected a DmcFingerContext"):
        env.reset_physics(dmc.DmcWalker.context_type.space.default(), np.random.default_rng(0))
    unchecked = env.default_context()  # built around validation, as a buggy caller might
    with pytest.raises(ContextError, match="gravity: value nan is not finite"):
        env.reset_physics(dataclasses.replace(unchecked, gravity=np.float32("nan")), None)
    with pytest.raises(ContextError, match=r"viscosity: value 11 is outside its bounds \[0, 10\]"):
        env.reset_physics(dataclasses.replace(unchecked, viscosity=np.float32(11)), None)
    # The upper bound itself is valid, in the float32 a context holds.
    env.reset_physics(env.context(limb_length_0=0.2, spinner_radius=0.05), np.random.default_rng(0))
    with pytest.raises(TypeError, match="numpy.random.Generator"):
        env.reset_physics(env.default_context(), 0)
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        env.step_physics(np.zeros(3))
    with pytest.raises(ValueError, match="not finite"):
        env.step_physics(np.array([np.nan, 0.0]))
    np.testing.assert_array_equal(rollout(env, env.default_context(), seed=2), expected)

    point_mass, _ = built["DmcPointMass"]
    with pytest.raises(ContextError, match=r"target_x=0.5 lies outside the arena"):
        point_mass.reset_physics(point_mass.context(target_x=0.5), np.random.default_rng(0))
    point_mass.reset_physics(
        point_mass.context(target_x=0.5, area_size=1.2), np.random.default_rng(0)
    )
    assert point_mass.physics.model.geom("target").pos[0] == 0.5

    with pytest.raises(ValueError, match=r"unknown task 'jump'.*'walk'"):
        dmc.DmcWalker("jump")
    with pytest.raises(ValueError, match="render_size"):
        dmc.DmcWalker(render_size=(0, 10))


# ---- rendering -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "name, changed",
    [
        ("DmcWalker", None),
        ("DmcQuadruped", None),
        ("DmcFish", None),
        ("DmcFinger", {"spinner_length": 0.36}),
        ("DmcPointMass", {"area_size": 1.2, "target_x": 0.4}),
    ],
)
@pytest.mark.egl
def test_rendering_is_headless_and_shows_the_geometry(name, changed):
    env = ENVS[name](render_size=(48, 64))
    env.reset_physics(env.default_context(), np.random.default_rng(0))
    frame = env.render_frame()
    assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8
    assert frame.std() > 5  # an image, not a blank
    if changed is not None:  # the geometry a context changes is visible
        env.reset_physics(env.context(**changed), np.random.default_rng(0))
        assert np.mean(np.any(env.render_frame() != frame, axis=-1)) > 0.005
    env.close()


def test_observation_layout_names_each_part_of_the_flat_observation(built):
    env, _ = built["DmcWalker"]
    assert env.observation_layout == {
        "orientations": slice(0, 14),
        "height": slice(14, 15),
        "velocity": slice(15, 24),
    }
    obs = env.reset_physics(env.default_context(), np.random.default_rng(0))
    assert obs[env.observation_layout["height"]][0] == np.float32(env.physics.torso_height())


def test_registered_under_their_names_and_carl_aliases():
    import contextrl as crl
    from contextrl.envs import DMC_ENVIRONMENTS

    assert crl.registered("dmc") == sorted(cls.__name__ for cls in dmc.ENVIRONMENTS)
    assert set(DMC_ENVIRONMENTS) == set(ENVS)
    env = crl.make("CARLDmcPointMassEnv", task="hard")
    assert isinstance(env, dmc.DmcPointMass) and env.task_name == "hard"
    assert crl.spec("CARLDmcPointMassEnv").host
