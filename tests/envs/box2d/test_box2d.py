"""The Box2D family: gymnasium parity at the default context, every feature acting, safe bounds,
isolation between instances, seeding, the gymnasium faces and the landing-in-space spec."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.helpers import ROOT

pytest.importorskip("Box2D")

import gymnasium  # noqa: E402

import contextrl  # noqa: E402  (also registers the gymnasium ids)
from contextrl.context.features import ContextError  # noqa: E402
from contextrl.envs.box2d import BipedalWalker, LunarLander  # noqa: E402

EXAMPLES = ROOT / "examples"


# ---- controllers that reach the states where each feature acts -------------------------------------
def lander_pilot(step: int, obs: np.ndarray, continuous: bool):
    """Fires the main engine to hover, then the side engines in turn, then lets the lander drop."""
    if step < 40:
        command = 2 if step % 3 else (1 if step % 2 else 3)
    elif step < 70:
        command = 0
    else:
        command = 2 if obs[3] < -0.3 else (1 if step % 2 else 3)
    if not continuous:
        return command
    main = 1.0 if command == 2 else -1.0
    lateral = {1: -0.9, 3: 0.9}.get(command, 0.0)
    return np.array([main, lateral], np.float32)


def walker_gait(step: int, obs: np.ndarray, continuous: bool = True) -> np.ndarray:
    """Swings the legs in opposition: every motor works, the feet push on the ground."""
    phase = np.sin(step / 6.0)
    return np.array([phase, -0.7 * phase, -phase, 0.7 * phase], np.float32)


def rollout(env, context, seed: int, steps: int, controller) -> tuple[np.ndarray, np.ndarray]:
    """Observations and rewards of one episode (stopped at ``steps`` or at its end)."""
    continuous = getattr(env, "continuous", True)
    obs = env.reset_physics(context, np.random.default_rng(seed))
    observations, rewards = [obs], []
    for step in range(steps):
        obs, reward, terminated = env.step_physics(controller(step, obs, continuous))
        observations.append(obs)
        rewards.append(reward)
        if terminated:
            break
    return np.array(observations), np.array(rewards)


# ---- parity with gymnasium ---------------------------------------------------------------------------
PARITY = [
    ("LunarLander-v3", {}, lambda: LunarLander(), {}, 1000),
    ("LunarLander-v3", {"continuous": True}, lambda: LunarLander(continuous=True), {}, 1000),
    (
        "LunarLander-v3",
        {"enable_wind": True, "wind_power": 15.0, "turbulence_power": 1.5},
        lambda: LunarLander(),
        {"wind_power": 15.0, "turbulence_power": 1.5},
        1000,
    ),
    ("BipedalWalker-v3", {}, lambda: BipedalWalker(), {}, 300),
    ("BipedalWalker-v3", {"hardcore": True}, lambda: BipedalWalker(), {"hardcore": "on"}, 300),
]


@pytest.mark.parametrize(
    "gym_id, gym_kwargs, build, context, steps",
    PARITY,
    ids=["discrete", "continuous", "wind", "walker", "hardcore"],
)
def test_default_context_is_gymnasium_step_by_step(gym_id, gym_kwargs, build, context, steps):
    original = gymnasium.make(gym_id, **gym_kwargs).unwrapped
    ours = build()
    action_rng = np.random.default_rng(7)
    for seed in (0, 1, 2):  # later episodes reuse each instance, as training does
        expected, _ = original.reset(seed=seed)
        obs = ours.reset_physics(ours.context(**context), np.random.default_rng(seed))
        np.testing.assert_array_equal(obs, expected)
        for _ in range(steps):
            action = _sample(original, action_rng)
            expected, expected_reward, expected_end, _, _ = original.step(action)
            obs, reward, terminated = ours.step_physics(action)
            np.testing.assert_array_equal(obs, expected)
            assert reward == expected_reward and terminated == expected_end
            if terminated:
                break
    original.close()


def _sample(env, rng: np.random.Generator):
    space = env.action_space
    if isinstance(space, gymnasium.spaces.Discrete):
        return int(rng.integers(space.n))
    return rng.uniform(space.low, space.high).astype(np.float32)


# ---- every feature acts ---------------------------------------------------------------------------
def probe_contexts(env) -> list[tuple[str, float]]:
    """Every feature at each bound that differs from its default (categoricals: every other choice)."""
    probes = []
    for name, f in env.context_space.features.items():
        for value in (f.lower, f.upper):
            if value != f.default:
                probes.append((name, value))
    return probes


@pytest.mark.parametrize(
    "build, controller, steps",
    [
        (lambda: LunarLander(), lander_pilot, 90),
        (lambda: LunarLander(continuous=True), lander_pilot, 90),
        (lambda: BipedalWalker(), walker_gait, 60),
    ],
    ids=["lander", "lander-continuous", "walker"],
)
def test_every_feature_changes_the_trajectory(build, controller, steps):
    env = build()
    base_obs, base_rewards = rollout(env, env.default_context(), 3, steps, controller)
    unchanged = []
    for name, value in probe_contexts(env):
        obs, rewards = rollout(env, env.context(**{name: value}), 3, steps, controller)
        same = obs.shape == base_obs.shape and np.array_equal(obs, base_obs)
        if same and np.array_equal(rewards, base_rewards):
            unchanged.append((name, value))
    assert not unchanged, f"features that changed nothing: {unchanged}"


def test_wind_pushes_the_lander_sideways_and_turbulence_turns_it():
    env = LunarLander()
    calm, _ = rollout(env, env.default_context(), 5, 30, lambda *_: 0)
    windy, _ = rollout(env, env.context(wind_power=20.0), 5, 30, lambda *_: 0)
    turbulent, _ = rollout(env, env.context(turbulence_power=2.0), 5, 30, lambda *_: 0)
    assert not np.allclose(windy[:, 2], calm[:, 2])  # horizontal velocity
    assert not np.allclose(turbulent[:, 5], calm[:, 5])  # angular velocity


def test_stronger_main_engine_climbs_faster_and_gravity_pulls_harder():
    env = LunarLander()
    full_throttle = lambda *_: 2  # noqa: E731
    weak, _ = rollout(env, env.context(MAIN_ENGINE_POWER=13.0), 0, 20, full_throttle)
    strong, _ = rollout(env, env.context(MAIN_ENGINE_POWER=40.0), 0, 20, full_throttle)
    assert strong[-1, 3] > weak[-1, 3]  # vertical velocity
    moon, _ = rollout(env, env.context(GRAVITY_Y=-1.63), 0, 20, lambda *_: 0)
    jupiter, _ = rollout(env, env.context(GRAVITY_Y=-23.1), 0, 20, lambda *_: 0)
    assert jupiter[-1, 3] < moon[-1, 3] < 0


def test_observation_keeps_its_meaning_under_viewport_and_scale():
    """x is 0 at the centre and ±1 at the world's edges; y measures from the pad, in half-heights."""
    env = LunarLander()
    context = env.context(SCALE=15.0, VIEWPORT_W=900, VIEWPORT_H=800, INITIAL_RANDOM=0.0)
    obs = env.reset_physics(context, np.random.default_rng(0))
    width, height = 900 / 15.0, 800 / 15.0
    pad_y, leg_down = height / 4, 18 / 15.0
    assert obs[0] == pytest.approx(0.0, abs=1e-6)
    # one step of free fall from the top: y barely below (height - pad - legs) / half-height
    assert obs[1] == pytest.approx((height - pad_y - leg_down) / (height / 2), abs=1e-3)
    assert env.pad_x[0] == pytest.approx(width / 10 * 4) and env.pad_x[1] == pytest.approx(
        width / 10 * 6
    )
    # fly sideways until the world's edge ends the episode at |x| = 1
    sideways = env.context(GRAVITY_Y=0.0, GRAVITY_X=20.0, INITIAL_RANDOM=0.0)
    env.reset_physics(sideways, np.random.default_rng(1))
    for _ in range(1000):
        obs, reward, terminated = env.step_physics(0)
        if terminated:
            break
    assert terminated and reward == -100.0 and obs[0] >= 1.0


def test_friction_reaches_every_ground_fixture_and_only_those():
    env = BipedalWalker()
    context = env.context(FRICTION=7.0, hardcore="on")
    env.reset_physics(context, np.random.default_rng(0))
    frictions = {np.float32(fixture.friction) for body in env.terrain for fixture in body.fixtures}
    polygons = [b for b in env.terrain if type(b.fixtures[0].shape).__name__ == "b2PolygonShape"]
    assert frictions == {np.float32(7.0)} and polygons  # edges and hardcore obstacles
    assert np.float32(env.hull.fixtures[0].friction) == np.float32(0.1)
    assert {np.float32(leg.fixtures[0].friction) for leg in env.legs} == {np.float32(0.2)}


def test_hardcore_builds_obstacles_and_normal_terrain_has_none():
    env = BipedalWalker()
    env.reset_physics(env.default_context(), np.random.default_rng(0))
    assert len(env.terrain) == env.default_context().TERRAIN_LENGTH - 1  # edges only
    env.reset_physics(env.context(hardcore="on"), np.random.default_rng(0))
    assert len(env.terrain) > 199


# ---- safe bounds ----------------------------------------------------------------------------------
def bound_contexts(env, count: int, seed: int) -> list:
    """All features at their lower bounds, all at their upper bounds, and random mixes of bounds."""
    space, rng = env.context_space, np.random.default_rng(seed)
    corners = [
        {name: f.lower for name, f in space.features.items()},
        {name: f.upper for name, f in space.features.items()},
    ]
    for _ in range(count):
        corners.append(
            {name: (f.lower, f.upper)[int(rng.integers(2))] for name, f in space.features.items()}
        )
    return [env.context(**values) for values in corners]


@pytest.mark.parametrize(
    "build, controller",
    [
        (lambda: LunarLander(), lander_pilot),
        (lambda: LunarLander(continuous=True), lander_pilot),
        (lambda: BipedalWalker(), walker_gait),
    ],
    ids=["lander", "lander-continuous", "walker"],
)
def test_contexts_at_the_bounds_run_and_stay_in_the_observation_space(build, controller):
    env = build()
    space = env.base_observation_space
    for index, context in enumerate(bound_contexts(env, 10, seed=0)):
        obs, rewards = rollout(env, context, index, 150, controller)
        assert all(space.contains(o) for o in obs), f"context {index}: {obs.min()} {obs.max()}"
        assert np.all(np.isfinite(rewards))
        frame = env.render_frame()
        assert frame.shape == (int(context.VIEWPORT_H), int(context.VIEWPORT_W), 3)


# ---- isolation and seeding ------------------------------------------------------------------------
def test_two_instances_with_different_contexts_do_not_leak_into_each_other():
    """CARL's leak: env A took env B's engine power after B reset. Here each keeps its own."""
    alone = LunarLander()
    expected, _ = rollout(alone, alone.context(MAIN_ENGINE_POWER=40.0), 4, 60, lander_pilot)
    first, second = LunarLander(), LunarLander()
    first.reset_physics(first.context(MAIN_ENGINE_POWER=40.0), np.random.default_rng(4))
    second.reset_physics(
        second.context(MAIN_ENGINE_POWER=1.0, SCALE=60.0), np.random.default_rng(9)
    )
    observations = [expected[0]]
    for step in range(60):
        obs, _, terminated = first.step_physics(lander_pilot(step, observations[-1], False))
        second.step_physics(2)
        observations.append(obs)
        if terminated:
            break
    np.testing.assert_array_equal(np.array(observations), expected)

    walker_alone = BipedalWalker()
    context = walker_alone.context(FRICTION=0.5, MOTORS_TORQUE=150.0)
    expected, _ = rollout(walker_alone, context, 2, 40, walker_gait)
    first, second = BipedalWalker(), BipedalWalker()
    first.reset_physics(context, np.random.default_rng(2))
    second.reset_physics(second.context(FRICTION=9.0, hardcore="on"), np.random.default_rng(3))
    observations = [expected[0]]
    for step in range(40):
        observations.append(first.step_physics(walker_gait(step, observations[-1]))[0])
        second.step_physics(walker_gait(step, observations[-1]))
    np.testing.assert_array_equal(np.array(observations), expected)


@pytest.mark.parametrize("env_id", ["LunarLander", "BipedalWalker"])
def test_reset_seed_reproduces_the_episode_through_gymnasium(env_id):
    env = gymnasium.make(
        f"contextrl/{env_id}-v0", contexts={"GRAVITY_Y": contextrl.Uniform(-15.0, -5.0)}
    )

    def episode(seed):
        obs, info = env.reset(seed=seed)
        env.action_space.seed(seed)
        rows = [obs]
        for _ in range(40):
            obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            rows.append(np.append(obs, reward))
            if terminated:
                break
        return np.concatenate(rows), info["context"]["GRAVITY_Y"]

    first, gravity = episode(11)
    again, gravity_again = episode(11)
    other, other_gravity = episode(12)
    np.testing.assert_array_equal(first, again)
    assert gravity == gravity_again != other_gravity
    assert first.shape != other.shape or not np.array_equal(first, other)
    env.close()


# ---- gymnasium faces ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "env_id, contexts",
    [
        ("LunarLander", {"wind_power": contextrl.Uniform(0.0, 20.0)}),
        ("LunarLanderContinuous", {"SCALE": contextrl.Uniform(10.0, 60.0)}),
        ("CARLBipedalWalker", {"FRICTION": contextrl.Uniform(0.5, 5.0)}),
    ],
)
@pytest.mark.filterwarnings("ignore::UserWarning")  # unbounded observations
def test_gymnasium_check_env_passes_with_resampled_visible_contexts(env_id, contexts):
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make(
        f"contextrl/{env_id}-v0",
        contexts=contexts,
        obs_context_features="all",
        render_mode="rgb_array",
    )
    check_env(env.unwrapped, skip_render_check=False)
    env.close()


def test_make_vec_gives_each_copy_its_context():
    envs = gymnasium.make_vec(
        "contextrl/CARLLunarLander-v0",
        num_envs=2,
        vectorization="sync",
        contexts=[
            {"GRAVITY_Y": -1.63, "INITIAL_RANDOM": 0.0},
            {"GRAVITY_Y": -23.1, "INITIAL_RANDOM": 0.0},
        ],
        obs_context_features=["GRAVITY_Y"],
    )
    obs, info = envs.reset(seed=0)
    np.testing.assert_allclose(obs[:, -1], [-1.63, -23.1], rtol=1e-6)
    for _ in range(10):
        obs, *_ = envs.step(np.zeros(2, np.int64))
    assert obs[1, 3] < obs[0, 3] < 0  # Jupiter pulls the second copy down faster
    envs.close()


def test_bad_input_is_refused_clearly():
    env = LunarLander()
    with pytest.raises(
        ContextError, match=r"GRAVITY_Y: value -30 is outside its bounds \[-25, 0.01\]"
    ):
        env.context(GRAVITY_Y=-30.0)
    with pytest.raises(ContextError, match="not finite"):
        env.context(FPS=float("nan"))
    with pytest.raises(ContextError, match="valid choice"):
        BipedalWalker().context(hardcore="extreme")
    with pytest.raises(RuntimeError, match="reset_physics"):
        env.step_physics(0)
    env.reset_physics(env.default_context(), np.random.default_rng(0))
    with pytest.raises(ValueError, match="integer in 0..3"):
        env.step_physics(4)
    with pytest.raises(ValueError, match="integer in 0..3"):
        env.step_physics(1.5)
    walker = BipedalWalker()
    walker.reset_physics(walker.default_context(), np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"shape \(4,\)"):
        walker.step_physics(np.zeros(3))
    with pytest.raises(ValueError, match="not finite"):
        walker.step_physics([0.0, np.nan, 0.0, 0.0])
    with pytest.raises(TypeError, match="Generator"):
        walker.reset_physics(walker.default_context(), 0)
    with pytest.raises(TypeError, match="continuous"):
        LunarLander(continuous="yes")


def test_registered_with_carl_aliases_and_variants():
    assert contextrl.registered("box2d")[:3] == [
        "BipedalWalker",
        "LunarLander",
        "LunarLanderContinuous",
    ]
    assert contextrl.spec("CARLLunarLander").id == "LunarLander"
    assert contextrl.spec("CARLBipedalWalker").id == "BipedalWalker"
    continuous = contextrl.make("LunarLanderContinuous")
    assert continuous.continuous and continuous.action_space.shape == (2,)
    assert gymnasium.make("contextrl/LunarLander-v0", continuous=True).action_space.shape == (2,)


# ---- landing in space ----------------------------------------------------------------------------
def test_landing_in_space_spec_validates_against_the_lander():
    """The paper's planets (CARL's g = 9.80665 multiples) against the spec's train and test regions."""
    from contextrl.experiments.protocols.train_test import region_of
    from contextrl.experiments.spec import load_yaml, parse_spec

    path = EXAMPLES / "box2d" / "train_test_landing_in_space.yaml"
    spec = parse_spec(load_yaml(path.read_text(), str(path)))
    spec.validate()
    train, test = spec.boxes()
    assert list(train) == ["GRAVITY_Y", "MAIN_ENGINE_POWER"]
    g = -9.80665
    planets = {"Moon": 0.166, "Mars": 0.377, "Pluto": 0.071, "Jupiter": 2.36, "Neptune": 1.12}
    boxes = list(train.values())
    region = {name: region_of((g * m, 13.0), boxes, "A", spec.band) for name, m in planets.items()}
    assert region["Moon"] == region["Mars"] == region["Pluto"] == "interpolation"
    assert region["Jupiter"] == region["Neptune"] == "extrapolation (one)"
    for multiple in planets.values():  # every planet inside the test grid and the bounds
        low, high = test["GRAVITY_Y"]
        assert low <= g * multiple <= high
        spec.space().make(GRAVITY_Y=g * multiple)


# ---- rendering ------------------------------------------------------------------------------------
def test_frames_show_the_context_and_the_cli_renders_the_family(tmp_path):
    from contextrl.cli import main

    def painted(env, context, color) -> int:
        env.reset_physics(context, np.random.default_rng(0))
        return int(np.all(env.render_frame() == color, axis=-1).sum())

    lander, walker = LunarLander(), BipedalWalker()
    purple = (128, 102, 230)
    short = painted(lander, lander.context(LEG_H=4.0, INITIAL_RANDOM=0.0), purple)
    long = painted(lander, lander.context(LEG_H=20.0, INITIAL_RANDOM=0.0), purple)
    assert long > short > 0
    far_leg = (178, 101, 152)  # sizes in metres are drawn at SCALE pixels per metre
    assert painted(walker, walker.context(LEG_H=2.0), far_leg) > painted(
        walker, walker.context(), far_leg
    )
    out = tmp_path / "walkers.gif"
    assert (
        main(
            [
                "render",
                "BipedalWalker",
                "--grid",
                "hardcore=off,on",
                "--steps",
                "3",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert out.stat().st_size > 0


@pytest.mark.skipif(not Path("/proc/self/statm").exists(), reason="reads Linux's /proc")
def test_resets_do_not_leak_memory():
    """pybox2d never frees a fixture definition; the environments reuse theirs (a definition per
    reset leaked about 1.6 kB per LunarLander reset and 0.9 kB per BipedalWalker reset)."""
    import os

    def resident() -> int:
        return int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE")

    for env, resets in ((LunarLander(), 1500), (BipedalWalker(), 1000)):
        context, rng = env.context(SCALE=25.0), np.random.default_rng(0)
        for _ in range(100):
            env.reset_physics(context, rng)
        before = resident()
        for _ in range(resets):
            env.reset_physics(context, rng)
        assert resident() - before < 400_000, env.name
