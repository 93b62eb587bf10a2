"""VehicleRacing: CarRacing-v3 parity, the garage, track features, isolation, seeding, gymnasium faces."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("Box2D")
pytest.importorskip("pygame")

import gymnasium  # noqa: E402
from gymnasium.envs.box2d.car_racing import CarRacing  # noqa: E402
from gymnasium.utils.env_checker import check_env  # noqa: E402

import contextrl  # noqa: E402, F401 - registers the gymnasium ids
from contextrl import ContextError  # noqa: E402
from contextrl.envs.box2d import GARAGE, VEHICLE_NAMES, VehicleRacing  # noqa: E402
from contextrl.envs.box2d.garage import UNIT  # noqa: E402


def actions(steps: int) -> np.ndarray:
    """A fixed driving sequence: full gas, then weaving with taps of the brake."""
    t = np.arange(steps)
    steer = np.where(t < 30, 0.0, np.sin(t / 15.0))
    gas = np.where(t < 100, 1.0, 0.4)
    brake = np.where(t % 40 == 39, 0.6, 0.0)
    return np.stack([steer, gas, brake], axis=1).astype(np.float32)


def drive(env: VehicleRacing, context, seed: int = 0, steps: int = 60):
    """Observations, rewards and hull poses of one seeded episode under ``actions``."""
    observations = [env.reset_physics(context, np.random.default_rng(seed))]
    rewards, poses = [], []
    for action in actions(steps):
        observation, reward, terminated = env.step_physics(action)
        observations.append(observation)
        rewards.append(reward)
        poses.append((*env.hull.position, env.hull.angle))
        if terminated:
            break
    return np.array(observations), np.array(rewards), np.array(poses)


@pytest.fixture(scope="module")
def env():
    return VehicleRacing()


# ---- parity with gymnasium's CarRacing-v3 --------------------------------------------------------


def test_default_context_is_car_racing_step_by_step(env):
    stock = CarRacing()
    for seed in (0, 5):  # two episodes: the second starts from a used environment on both sides
        observation = env.reset_physics(env.default_context(), np.random.default_rng(seed))
        expected, _ = stock.reset(seed=seed)
        np.testing.assert_array_equal(observation, expected)
        assert len(env.track) == len(stock.track)
        for step, action in enumerate(actions(250 if seed == 0 else 60)):
            observation, reward, terminated = env.step_physics(action)
            expected, expected_reward, expected_terminated, _, _ = stock.step(action)
            np.testing.assert_array_equal(observation, expected, err_msg=f"step {step}")
            assert reward == expected_reward, step
            assert terminated == expected_terminated, step
            if terminated:
                break
        assert env.visited_count == stock.tile_visited_count > 5  # the car really drove the track


def test_discrete_actions_and_rgb_frames_match_car_racing():
    env = VehicleRacing(continuous=False)
    stock = CarRacing(continuous=False, render_mode="rgb_array")
    env.reset_physics(env.default_context(), np.random.default_rng(3))
    stock.reset(seed=3)
    for step in range(120):
        action = 3 if step < 40 else (3, 3, 1, 3, 2, 4, 0)[step % 7]
        observation, reward, terminated = env.step_physics(action)
        expected, expected_reward, expected_terminated, _, _ = stock.step(action)
        np.testing.assert_array_equal(observation, expected)
        assert (reward, terminated) == (expected_reward, expected_terminated)
        if step % 40 == 39:  # the 600×400 frame, skid marks included
            np.testing.assert_array_equal(env.render_frame(), stock.render())


def test_gymnasium_make_is_car_racing_at_the_default_context():
    """Through the adapter: the episode's generator is the seeded one after the adapter's key draw."""
    env = gymnasium.make("contextrl/VehicleRacing-v0")
    stock = CarRacing()
    observation, info = env.reset(seed=11)
    generator = np.random.default_rng(11)
    generator.integers(2**32, dtype=np.uint64)  # what the adapter draws for its episode keys
    stock.np_random = generator
    expected, _ = stock.reset()
    np.testing.assert_array_equal(observation, expected)
    assert info["context"]["vehicle"] == "race_car_rwd"
    for action in actions(60):
        observation, reward, terminated, truncated, _ = env.step(action)
        expected, expected_reward, expected_terminated, _, _ = stock.step(action)
        np.testing.assert_array_equal(observation, expected)
        assert (reward, terminated, truncated) == (expected_reward, expected_terminated, False)


# ---- the garage -----------------------------------------------------------------------------------


def test_garage_holds_carls_29_vehicles_in_carls_order():
    assert len(GARAGE) == 29
    assert VEHICLE_NAMES[:3] == ("race_car_rwd", "race_car_fwd", "race_car_awd")
    assert VEHICLE_NAMES[3] == "race_car_rwd_small_trailer"
    assert VEHICLE_NAMES[8] == "race_car_awd_large_trailer"
    assert VEHICLE_NAMES[9] == "street_car_rwd" and VEHICLE_NAMES[18] == "bus_rwd"
    assert VEHICLE_NAMES[27:] == ("tuk_tuk_rwd", "tuk_tuk_rwd_small_trailer")
    space = VehicleRacing.context_type.space
    assert space.features["vehicle"].default_label() == "race_car_rwd"
    assert space.make(VEHICLE_ID=19).vehicle == 19  # CARL's integer id picks the same vehicle


def test_every_vehicle_is_built_as_declared(env):
    total_masses = {}
    for index, vehicle in enumerate(GARAGE):
        env.reset_physics(env.context(vehicle=index), np.random.default_rng(0))
        assert env.vehicle is vehicle
        assert len(env.wheels) == len(vehicle.all_wheels)
        driven = [w.spec for w in env.wheels if w.spec.driven]
        assert driven == [w for w in vehicle.wheels if w.driven] and driven
        if "_fwd" in vehicle.name:
            assert all(w.y > 0 for w in driven)
        elif "_awd" in vehicle.name:
            assert len(driven) == 4
        else:
            assert all(w.y < 0 for w in driven)
        total_masses[vehicle.name] = sum(body.mass for body in env.world.bodies)
    # Each body style and trailer weighs something else; the drive does not change the mass.
    assert total_masses["race_car_rwd"] == total_masses["race_car_awd"]
    styles = ("race_car_rwd", "street_car_rwd", "bus_rwd", "tuk_tuk_rwd")
    assert len({total_masses[name] for name in styles}) == 4
    for style in ("race_car_rwd", "street_car_rwd", "bus_rwd"):
        assert (
            total_masses[style]
            < total_masses[f"{style}_small_trailer"]
            < total_masses[f"{style}_large_trailer"]
        )
    powers = {v.name.split("_rwd")[0]: v.engine_power for v in GARAGE if v.name.endswith("rwd")}
    assert powers["race_car"] == 100_000_000 * UNIT**2 > powers["bus"] > powers["tuk_tuk"]
    assert powers["tuk_tuk"] > powers["street_car"]


def test_every_vehicle_drives_its_own_trajectory(env):
    ends = {}
    for name in VEHICLE_NAMES:
        _, _, poses = drive(env, env.context(vehicle=name), steps=25)
        assert np.all(np.isfinite(poses))
        ends[name] = tuple(np.round(poses[-1], 6))
    assert len(set(ends.values())) == len(VEHICLE_NAMES)


@pytest.mark.parametrize("name", ["race_car_rwd_small_trailer", "bus_awd_large_trailer"])
def test_trailers_are_hitched_and_follow(env, name):
    env.reset_physics(env.context(vehicle=name), np.random.default_rng(2))
    trailer = env.vehicle.trailer
    assert len(env.joints) == len(trailer.bodies)
    first = env.joints[0]
    assert first.bodyA == env.hull and first.bodyB != env.hull
    trailer_body = env.joints[-1].bodyB
    start_hull = np.array(env.hull.position)
    start_trailer = np.array(trailer_body.position)
    for _ in range(120):
        env.step_physics(np.array([0.0, 1.0, 0.0]))
    moved_hull = np.array(env.hull.position) - start_hull
    moved_trailer = np.array(trailer_body.position) - start_trailer
    assert np.linalg.norm(moved_hull) > 10.0
    np.testing.assert_allclose(moved_trailer, moved_hull, atol=0.1 * np.linalg.norm(moved_hull))
    for joint in env.joints:  # the hitches hold: both bodies' anchors stay together
        assert np.linalg.norm(np.array(joint.anchorA) - np.array(joint.anchorB)) < 0.05


# ---- track features -------------------------------------------------------------------------------

TRACK_CHANGES = {"track_turn_rate": 0.8, "track_width": 3.0, "checkpoints": 20}


@pytest.mark.parametrize("name", list(TRACK_CHANGES))
def test_every_track_feature_changes_the_track_and_the_trajectory(env, name):
    observations, rewards, poses = drive(env, env.default_context())
    polygons = env.road_polygons.copy()
    changed = env.context(**{name: TRACK_CHANGES[name]})
    changed_observations, changed_rewards, changed_poses = drive(env, changed)
    assert polygons.shape != env.road_polygons.shape or not np.allclose(polygons, env.road_polygons)
    assert not np.array_equal(observations, changed_observations)
    assert not np.array_equal(rewards, changed_rewards)
    if name == "track_width":  # the same layout, a narrower road: the weaving car leaves it
        tile = env.road_polygons[0]
        assert np.linalg.norm(tile[0] - tile[1]) == pytest.approx(2 * 3.0)
        assert not np.array_equal(poses, changed_poses)


def test_contexts_at_the_bounds_run_and_stay_inside_the_observation_space(env):
    space = env.base_observation_space
    for turn_rate, width, checkpoints in ((0.05, 3.0, 8), (1.0, 15.0, 32)):
        context = env.context(
            vehicle="bus_awd_large_trailer",
            track_turn_rate=turn_rate,
            track_width=width,
            checkpoints=checkpoints,
        )
        observation = env.reset_physics(context, np.random.default_rng(4))
        for action in actions(30):
            observation, reward, _ = env.step_physics(action)
            assert space.contains(observation) and np.isfinite(reward)


# ---- isolation, seeding, errors -------------------------------------------------------------------


def test_two_instances_with_different_vehicles_stay_isolated():
    alone_bus = drive(VehicleRacing(), VehicleRacing().context(vehicle="bus_fwd"), seed=1)
    alone_car = drive(VehicleRacing(), VehicleRacing().default_context(), seed=1)
    bus, car = VehicleRacing(), VehicleRacing()
    rows = {id(bus): ([], []), id(car): ([], [])}
    bus_obs = bus.reset_physics(bus.context(vehicle="bus_fwd"), np.random.default_rng(1))
    car_obs = car.reset_physics(car.default_context(), np.random.default_rng(1))
    rows[id(bus)][0].append(bus_obs)
    rows[id(car)][0].append(car_obs)
    for action in actions(60):  # interleaved: each step of one between steps of the other
        for env in (bus, car):
            observation, reward, _ = env.step_physics(action)
            rows[id(env)][0].append(observation)
            rows[id(env)][1].append(reward)
    np.testing.assert_array_equal(np.array(rows[id(bus)][0]), alone_bus[0])
    np.testing.assert_array_equal(np.array(rows[id(car)][0]), alone_car[0])
    np.testing.assert_array_equal(np.array(rows[id(bus)][1]), alone_bus[1])


def test_reset_with_a_seed_is_reproducible():
    env = gymnasium.make("contextrl/VehicleRacing-v0", contexts={"vehicle": "tuk_tuk_rwd"})

    def episode(seed):
        rows = [env.reset(seed=seed)[0]]
        for action in actions(40):
            rows.append(env.step(action)[0])
        return np.array(rows)

    first = episode(7)
    episode(8)  # something else in between
    np.testing.assert_array_equal(episode(7), first)
    assert not np.array_equal(episode(8), first)


def test_bad_input_is_refused_with_clear_errors(env):
    with pytest.raises(ContextError, match="not a valid choice.*race_car_rwd"):
        env.context(vehicle="truck")
    with pytest.raises(
        ContextError, match=r"track_width: value 40 is outside its bounds \[3, 15\]"
    ):
        env.context(track_width=40.0)
    with pytest.raises(ContextError, match="checkpoints: expected an integer"):
        env.context(checkpoints=12.5)
    with pytest.raises(ContextError, match="not finite"):
        env.context(track_turn_rate=float("nan"))
    env.reset_physics(env.default_context(), np.random.default_rng(0))
    with pytest.raises(ValueError, match="3 finite numbers"):
        env.step_physics(np.array([0.0, np.nan, 0.0]))
    with pytest.raises(ValueError, match="3 finite numbers"):
        env.step_physics(np.zeros(2))
    discrete = VehicleRacing(continuous=False)
    discrete.reset_physics(discrete.default_context(), np.random.default_rng(0))
    with pytest.raises(ValueError, match="one of 0..4"):
        discrete.step_physics(7)
    with pytest.raises(ValueError, match="lap_complete_percent"):
        VehicleRacing(lap_complete_percent=1.5)


# ---- gymnasium faces ------------------------------------------------------------------------------


def test_gymnasium_check_env_passes():
    for kwargs in (
        {"contexts": {"vehicle": "street_car_awd_small_trailer"}},
        {"continuous": False},
    ):
        env = gymnasium.make("contextrl/VehicleRacing-v0", render_mode="rgb_array", **kwargs)
        assert env.observation_space == gymnasium.spaces.Box(0, 255, (96, 96, 3), np.uint8)
        check_env(env.unwrapped)
        env.reset(seed=0)
        assert env.render().shape == (400, 600, 3)


def test_make_vec_gives_each_copy_its_context():
    names = ["bus_rwd", "tuk_tuk_rwd_small_trailer"]
    envs = gymnasium.make_vec(
        "contextrl/CARLVehicleRacing-v0",
        num_envs=2,
        vectorization="sync",
        contexts=[{"vehicle": name} for name in names],
    )
    observations, info = envs.reset(seed=0)
    assert observations.shape == (2, 96, 96, 3) and observations.dtype == np.uint8
    assert list(info["context"]["vehicle"]) == names
    vehicles = [env.vehicle.name for env in envs.get_attr("contextrl_env")]
    assert vehicles == names
    for _ in range(5):
        observations, *_ = envs.step(np.tile([0.0, 1.0, 0.0], (2, 1)).astype(np.float32))
    assert not np.array_equal(observations[0], observations[1])
    envs.close()


def test_a_visible_context_comes_beside_the_pixels():
    env = gymnasium.make(
        "contextrl/VehicleRacing-v0",
        contexts=[{"vehicle": "bus_rwd"}, {"vehicle": "tuk_tuk_rwd", "track_width": 5.0}],
        obs_context_features="varying",
        obs_context_as_dict=True,
    )
    assert env.observation_space["obs"] == gymnasium.spaces.Box(0, 255, (96, 96, 3), np.uint8)
    first, _ = env.reset(seed=0)
    second, _ = env.reset()
    assert first["obs"].dtype == np.uint8 and env.observation_space.contains(second)
    np.testing.assert_allclose(first["context"], [VEHICLE_NAMES.index("bus_rwd"), 20 / 3])
    np.testing.assert_allclose(second["context"], [VEHICLE_NAMES.index("tuk_tuk_rwd"), 5.0])
    flat = gymnasium.make(
        "contextrl/VehicleRacing-v0", contexts={"vehicle": "bus_rwd"}, obs_context_features="all"
    )
    observation, _ = flat.reset(seed=0)
    np.testing.assert_array_equal(observation[:-4].reshape(96, 96, 3), first["obs"])


def test_leaving_the_playfield_ends_the_episode_as_car_racing_does():
    env = gymnasium.make("contextrl/VehicleRacing-v0", contexts={"vehicle": "race_car_fwd"})
    _, info = env.reset(seed=0)
    assert "lap_finished" not in info
    steps, terminated, truncated = 0, False, False
    while not (terminated or truncated) and steps < 600:  # straight on at full throttle
        _, reward, terminated, truncated, info = env.step(np.array([0.0, 1.0, 0.0], np.float32))
        steps += 1
    assert terminated and not truncated and steps > 50
    assert reward == -100.0 and info["lap_finished"] is False
    assert max(map(abs, env.unwrapped.contextrl_env.hull.position)) > 2000 / 6
