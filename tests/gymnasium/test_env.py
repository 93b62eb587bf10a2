"""The single gymnasium adapter: gymnasium's checker, parity with CartPole-v1, contexts, seeding, errors."""

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import contextrl as crl
from contextrl.context import RESAMPLED_ID
from contextrl.gymnasium import ContextualGymEnv, ContextualVectorEnv, gym_id, register_envs

LENGTHS = [{"length": 0.25}, {"length": 1.0}]
OBS_MODES = [
    {"obs_context_features": None},
    {"obs_context_features": "all"},
    {
        "obs_context_features": "varying",
        "obs_context_normalize": True,
        "obs_context_as_dict": True,
        "obs_context_noise": 0.1,
    },
]


def _two_contexts(env_id):
    """Two contexts of an env that differ in their first feature (for the "varying" mode)."""
    space = crl.spec(env_id).factory().context_space
    name = space.names[0]
    feature = space.features[name]
    other = feature.lower if feature.default != feature.lower else feature.upper
    return [{name: feature.default}, {name: other}]


# Brax's gymnasium face is checked in test_brax_agents.py on one task (each mode would compile MJX again).
@pytest.mark.parametrize("env_id", [i for i in crl.registered() if crl.spec(i).family != "brax"])
def test_gymnasium_check_env_passes_in_every_observation_mode(env_id):
    for mode in OBS_MODES:
        env = gymnasium.make(gym_id(env_id), contexts=_two_contexts(env_id), **mode)
        check_env(env.unwrapped, skip_render_check=True)
        obs, _ = env.reset(seed=3)
        assert env.observation_space.contains(obs)
        for _ in range(5):
            obs, *_ = env.step(env.action_space.sample())
            assert env.observation_space.contains(obs)
        env.close()


def test_default_context_matches_gymnasium_cartpole_step_by_step():
    ours = gymnasium.make("contextrl/CartPole-v0")
    theirs = gymnasium.make("CartPole-v1").unwrapped
    obs, _ = ours.reset(seed=0)
    theirs.reset(seed=0)
    actions = np.random.default_rng(0).integers(0, 2, 200)
    steps = 0
    for action in actions:
        steps += 1
        theirs.state = obs.astype(np.float64)
        expected, reward, terminated, _, _ = theirs.step(int(action))
        obs, our_reward, our_terminated, truncated, _ = ours.step(int(action))
        np.testing.assert_allclose(obs, expected, rtol=1e-5, atol=1e-6)
        assert (our_reward, our_terminated, truncated) == (reward, terminated, False)
        if terminated:
            break
    assert steps > 5


def test_length_changes_the_trajectory_and_info_reports_the_context():
    short = ContextualGymEnv("CartPole", contexts={"length": 0.25})
    long = ContextualGymEnv("CartPole", contexts={"pole_length": 2.0})  # paper alias
    a, info_a = short.reset(seed=1)
    b, info_b = long.reset(seed=1)
    np.testing.assert_array_equal(a, b)  # same seed, same start state
    assert info_a["context"]["length"] == 0.25 and info_b["context"]["length"] == 2.0
    for _ in range(10):
        a, *_ = short.step(1)
        b, *_ = long.step(1)
    assert abs(a[3]) > abs(b[3]) * 2  # a short pole falls faster


def test_time_limit_is_owned_by_the_adapter():
    env = gymnasium.make("contextrl/MountainCar-v0", max_steps=7)
    env.reset(seed=0)
    flags = [env.step(1)[3] for _ in range(7)]
    assert flags == [False] * 6 + [True]


def test_round_robin_static_mapping_ids_and_callable_selector():
    env = ContextualGymEnv("CartPole", contexts={"short": LENGTHS[0], "long": LENGTHS[1]})
    ids = [env.reset(seed=0 if i == 0 else None)[1]["context_id"] for i in range(5)]
    assert ids == ["short", "long", "short", "long", "short"]
    static = ContextualGymEnv("CartPole", contexts=LENGTHS, context_selector="static")
    assert {static.reset()[1]["context_id"] for _ in range(4)} == {0}
    last = ContextualGymEnv("CartPole", contexts=LENGTHS, context_selector=lambda k, e, n: n - 1)
    assert [last.reset()[1]["context"]["length"] for _ in range(3)] == [1.0, 1.0, 1.0]


def test_random_selector_and_resampling_follow_the_seed_not_global_rng():
    batch = crl.sample(crl.make("CartPole"), {"length": crl.Uniform(0.1, 2.0)}, 16, key=_key(0))

    def run(seed, contexts, selector=None):
        env = ContextualGymEnv(
            "CartPole", contexts=contexts, context_selector=selector, obs_context_features="all"
        )
        episodes = []
        for episode in range(6):
            obs, info = env.reset(seed=seed if episode == 0 else None)
            trace = [obs]
            for _ in range(3):
                trace.append(env.step(0)[0])
            episodes.append((info["context_id"], info["context"]["length"], np.stack(trace)))
        return episodes

    for contexts, selector in ((batch, "random"), ({"length": crl.Uniform(0.1, 2.0)}, None)):
        np.random.seed(0)
        first = run(7, contexts, selector)
        state = np.random.get_state()
        np.random.seed(123)
        second = run(7, contexts, selector)
        assert np.random.get_state()[1].tolist() != state[1].tolist()  # reseeded: different global
        for (id_a, len_a, obs_a), (id_b, len_b, obs_b) in zip(first, second, strict=True):
            assert (id_a, len_a) == (id_b, len_b)
            np.testing.assert_array_equal(obs_a, obs_b)
        other = run(8, contexts, selector)
        assert [e[1] for e in other] != [e[1] for e in first]
        assert len({e[1] for e in first}) > 2  # the context really changes between episodes
    assert all(e[0] == RESAMPLED_ID for e in run(1, {"length": crl.Uniform(0.1, 2.0)}))


def test_reset_options_switch_the_context_for_one_episode():
    env = ContextualGymEnv("CartPole", contexts={"a": LENGTHS[0], "b": LENGTHS[1]})
    assert env.reset(seed=0)[1]["context_id"] == "a"
    _, info = env.reset(options={"context": {"length": 3.0}})
    assert info["context_id"] == RESAMPLED_ID and info["context"]["length"] == 3.0
    assert env.step(0)[4]["context"]["length"] == 3.0
    assert env.reset(options={"context_id": "b"})[1]["context"]["length"] == 1.0
    assert env.reset()[1]["context_id"] == "b"  # round robin goes on: a, (3.0), (b), b
    with pytest.raises(crl.ContextError, match="outside its bounds"):
        env.reset(options={"context": {"length": 50.0}})
    with pytest.raises(crl.ContextError, match="not an id"):
        env.reset(options={"context_id": "c"})


def test_dict_observation_splits_obs_and_context():
    env = gymnasium.make(
        "contextrl/Pendulum-v0",
        contexts=[{"l": 0.5}, {"l": 2.0}],
        obs_context_features="varying",
        obs_context_as_dict=True,
    )
    obs, _ = env.reset(seed=0)
    assert set(obs) == {"obs", "context"} and obs["obs"].shape == (3,)
    np.testing.assert_allclose(obs["context"], [0.5])
    obs, *_ = env.step(np.array([0.5], np.float32))
    assert env.observation_space.contains(obs)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"contexts": {"lenght": 0.5}}, "unknown context feature 'lenght'"),
        ({"contexts": {"length": 9.0}}, r"length: value 9 is outside its bounds \[0.05, 5\]"),
        ({"contexts": {"length": float("nan")}}, "not finite"),
        ({"contexts": {"length": "long"}}, "expected a number"),
        ({"contexts": LENGTHS, "context_selector": "first"}, "unknown context selector 'first'"),
        ({"obs_context_features": "some"}, "unknown context observation mode 'some'"),
        ({"obs_context_features": ["length", "mass"]}, "unknown context feature 'mass'"),
        ({"obs_context_as_dict": True}, "needs visible context features"),
        ({"contexts": {"length": crl.Uniform(0.1, 9.0)}}, "outside the feature's bounds"),
        ({"contexts": {"length": crl.Uniform(0.1, 1)}, "context_selector": "random"}, "drop"),
        ({"contexts": []}, "contexts must be"),
        ({"render_mode": "ansi"}, "render_mode"),
        ({"max_steps": 0}, "max_steps"),
    ],
)
def test_bad_input_is_refused_at_construction(kwargs, message):
    with pytest.raises((crl.ContextError, ValueError), match=message):
        ContextualGymEnv("CartPole", **kwargs)


def test_bad_actions_are_refused():
    env = gymnasium.make("contextrl/CartPole-v0", disable_env_checker=True)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="integer in"):
        env.step(2)
    pendulum = gymnasium.make("contextrl/Pendulum-v0", disable_env_checker=True)
    pendulum.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        pendulum.step(np.array([np.nan], np.float32))


# One face of each kind: a JAX env on its scalar host path, in compiled programs (a noisy context
# observation draws at every step), in the vector env, and a host simulator (Box2D).
ACTION_FACES = {
    "scalar physics": lambda: ContextualGymEnv("Pendulum"),
    "compiled": lambda: ContextualGymEnv(
        "Pendulum", obs_context_features="all", obs_context_noise=0.1
    ),
    "vector": lambda: ContextualVectorEnv("Pendulum", num_envs=2),
    "host": lambda: ContextualGymEnv("LunarLanderContinuous"),
}


@pytest.mark.parametrize("face", ACTION_FACES)
def test_every_face_clips_finite_box_actions_and_refuses_the_rest(face):
    env = ACTION_FACES[face]()
    vector = isinstance(env, gymnasium.vector.VectorEnv)
    space = env.single_action_space if vector else env.action_space
    shape = (env.num_envs, *space.shape) if vector else space.shape

    def trajectory(action: np.ndarray) -> np.ndarray:
        env.reset(seed=0)
        return np.stack([env.step(np.broadcast_to(action, shape))[0] for _ in range(5)])

    upper = np.resize([True, False], space.shape)  # one value above its bounds, the next below
    beyond = trajectory(np.where(upper, 3 * space.high, 3 * space.low))
    np.testing.assert_array_equal(beyond, trajectory(np.where(upper, space.high, space.low)))
    for bad in (
        np.full(shape, np.nan),
        np.full(shape, np.inf),
        np.zeros((7,)),
        np.full(shape, "a"),
    ):
        with pytest.raises(
            ValueError, match=r"must be (a finite float array|finite floats) of shape"
        ):
            env.step(bad)
    env.close()


def test_every_id_and_alias_is_registered_and_later_ids_are_picked_up():
    for env_id in crl.registered():
        for name in (env_id, *crl.spec(env_id).aliases):
            assert gym_id(name) in gymnasium.registry
    assert register_envs() == []  # idempotent
    crl.register("TestShortCartPole", _short_cartpole, family="test")
    try:
        assert register_envs() == ["contextrl/TestShortCartPole-v0"]
        env = gymnasium.make("contextrl/TestShortCartPole-v0")
        env.reset(seed=0)
        assert [env.step(0)[3] for _ in range(3)] == [False, False, True]
    finally:
        from contextrl.core import registry

        registry._REGISTRY.pop("TestShortCartPole")
        gymnasium.registry.pop("contextrl/TestShortCartPole-v0")


def _short_cartpole(**kwargs):
    kwargs["max_steps"] = kwargs.get("max_steps") or 3
    return crl.make("CartPole", **kwargs)


def _key(seed):
    import jax

    return jax.random.key(seed)
