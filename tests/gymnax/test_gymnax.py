"""The gymnax face: gymnax's calls and conventions over the core, params as contexts, PPO learning."""

import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import contextrl as crl
import contextrl.gymnax as gymnax
from contextrl.core.spaces import Box, Discrete
from tests.helpers import learning

# Of Brax, whose MJX programs take minutes to compile on a CPU, the cheapest task on brax's positional
# pipeline (about half MJX's compile time): its ten envs share one base and every pipeline the same
# env methods, so the face's calls are the same for all of them (test_brax.py covers MJX's physics).
FACE_ENVS = [
    name
    for name in gymnax.registered_envs  # a list, as gymnax's: its ids where gymnax has the env
    if crl.spec(name.split("-v")[0]).family != "brax" or name == "BraxInvertedPendulum"
]
ENV_OPTIONS = {"BraxInvertedPendulum": {"backend": "positional"}}


@pytest.mark.parametrize("env_id", FACE_ENVS)
def test_every_jax_env_has_the_gymnax_calls(env_id):
    env, params = gymnax.make(env_id, **ENV_OPTIONS.get(env_id, {}))
    core = crl.make(env_id.split("-v")[0], **ENV_OPTIONS.get(env_id, {}))
    assert params == core.default_context()
    key = jax.random.key(0)
    obs, state = jax.jit(env.reset)(key, params)  # compiled, as gymnax's users call it
    assert obs.shape == env.observation_space(params).shape
    action = env.action_space(params).sample(jax.random.key(1))
    obs, state, reward, done, info = jax.jit(env.step)(jax.random.key(2), state, action, params)
    core_state, _ = jax.jit(core.reset)(key, params)
    _, timestep = jax.jit(core.step)(jax.random.key(2), core_state, action, params)
    np.testing.assert_array_equal(obs, timestep.obs)  # the face is the core's step
    assert float(reward) == float(timestep.reward) and bool(done) == bool(timestep.done)
    assert set(info) == {"terminated", "truncated", "discount", "final_observation"}
    space = core.action_space
    assert env.num_actions == (space.n if hasattr(space, "n") else space.shape[0])


def test_ids_in_gymnax_and_carl_spelling_and_clear_errors():
    assert gymnax.make("CartPole-v1")[0].name == gymnax.make("CARLCartPole")[0].name == "CartPole"
    assert gymnax.make("MountainCarContinuous-v0")[0].name == "MountainCarContinuous"
    with pytest.raises(KeyError, match="unknown environment"):
        gymnax.make("CartPoel-v1")
    if "DmcWalker" in crl.registered():
        with pytest.raises(ValueError, match="steps on the host"):
            gymnax.make("DmcWalker")


def test_auto_reset_keeps_the_final_observation_and_flags_termination():
    env, params = gymnax.make("CartPole")
    obs, state = env.reset(jax.random.key(0), params)
    for t in range(100):
        previous = obs
        obs, state, reward, done, info = env.step(jax.random.key(t + 1), state, 1, params)
        if done:
            break
    assert bool(done) and bool(info["terminated"]) and not bool(info["truncated"])
    assert float(info["discount"]) == 0.0 and float(reward) == 1.0
    final = np.asarray(info["final_observation"])
    assert abs(final[2]) > 12 * 2 * np.pi / 360 or abs(final[0]) > 2.4  # the pole fell
    assert not np.array_equal(final, previous)
    assert np.all(np.abs(np.asarray(obs)) <= 0.05)  # already the next episode's start
    assert int(state.time) == 0


def test_truncation_at_the_time_limit_is_not_a_termination():
    env, params = gymnax.make("Pendulum", max_steps=4)
    obs, state = env.reset(jax.random.key(0), params)
    flags = []
    for t in range(4):
        obs, state, _, done, info = env.step(jax.random.key(t), state, jnp.zeros(1), params)
        flags.append((bool(done), bool(info["truncated"]), float(info["discount"])))
    assert flags == [(False, False, 1.0)] * 3 + [(True, True, 1.0)]


def test_params_are_contexts_and_vmap_gives_each_copy_its_own():
    env, params = gymnax.make("CartPole")
    assert float(params.replace(length=0.8).length) == pytest.approx(0.8)
    with pytest.raises(crl.ContextError, match="length"):
        params.replace(length=50.0)
    batch = crl.sample(params, {"length": crl.Uniform(0.25, 2.0)}, 4, jax.random.key(0))
    keys = jax.random.split(jax.random.key(1), 4)
    same_key = jnp.broadcast_to(jax.random.key(1), (4,))
    obs, state = jax.vmap(env.reset)(same_key, batch)
    np.testing.assert_array_equal(obs[0], obs[3])  # same key, same start state
    step = jax.jit(jax.vmap(env.step))
    for _ in range(10):
        obs, state, *_ = step(keys, state, jnp.ones(4, jnp.int32), batch)
    assert len({tuple(np.round(np.asarray(o), 6)) for o in obs}) == 4  # each pole its own motion
    single_obs, single_state = env.reset(jax.random.key(1), batch[2])
    for _ in range(10):
        single_obs, single_state, *_ = env.step(keys[2], single_state, 1, batch[2])
    np.testing.assert_allclose(single_obs, obs[2], rtol=1e-6)


@pytest.mark.slow  # PPO learns CartPole in tests/agents/test_ppo.py; the gymnax calls: above
def test_purejaxrl_style_ppo_learns_contextual_cartpole():
    """examples/purejaxrl_ppo_cartpole.py unchanged (100k steps, a pole length per copy), seeds 0–3 in
    one vmapped call: the mean return of the first 5 updates and of the last 10 %.

    Measured (tests/helpers/margins.py), the last updates' mean return: default numerics, seeds
    0–15: min 260, median 488; fast math, seeds 100–107: min 410, median 469. The first updates:
    31–42. Every seed >= 150 and the median of the four >= 350 hold with a margin (the worst four
    measured give 404).
    """
    statistics = learning.purejaxrl_cartpole(range(4))
    first, last = statistics["first_updates"], statistics["last_updates"]
    assert np.all(first < 60), first
    assert np.all(last >= 150) and np.median(last) >= 350, last


# ---- PureJaxRL's wrappers check gymnax's own space classes ----------------------------------------------
class SpaceCheckingFlatten:
    """PureJaxRL's ``FlattenObservationWrapper``: refuses any space that is not gymnax's own class."""

    def __init__(self, env, params):
        from gymnax.environments import spaces

        assert isinstance(env.observation_space(params), spaces.Box), (
            "Only Box spaces are supported"
        )
        assert isinstance(env.action_space(params), spaces.Discrete)
        self._env = env

    def __getattr__(self, name):
        return getattr(self._env, name)

    def reset(self, key, params):
        obs, state = self._env.reset(key, params)
        return jnp.reshape(obs, (-1,)), state

    def step(self, key, state, action, params):
        obs, state, reward, done, info = self._env.step(key, state, action, params)
        return jnp.reshape(obs, (-1,)), state, reward, done, info


class EpisodeReturns(SpaceCheckingFlatten):
    """PureJaxRL's ``LogWrapper``: the running return, and the return of each finished episode."""

    def reset(self, key, params):
        obs, state = super().reset(key, params)
        return obs, (state, jnp.float32(0.0), jnp.float32(0.0))

    def step(self, key, state, action, params):
        env_state, running, _ = state
        obs, env_state, reward, done, info = super().step(key, env_state, action, params)
        running = running + reward
        info["returned_episode_return"] = jnp.where(done, running, 0.0)
        return (
            obs,
            (env_state, running * (1 - done), info["returned_episode_return"]),
            reward,
            done,
            info,
        )


def test_purejaxrl_wrappers_see_gymnax_space_classes_and_run_300_steps():
    env, params = gymnax.make("CartPole-v1")
    wrapped = EpisodeReturns(env, params)
    batch = crl.sample(params, {"length": crl.Uniform(0.25, 2.0)}, 8, jax.random.key(0))
    obs, state = jax.vmap(wrapped.reset)(jax.random.split(jax.random.key(1), 8), batch)
    assert obs.shape == (8, *wrapped.observation_space(params).shape)

    def one_step(carry, key):
        state = carry
        action_key, step_key = jax.random.split(key)
        actions = jax.vmap(wrapped.action_space(params).sample)(jax.random.split(action_key, 8))
        obs, state, reward, done, info = jax.vmap(wrapped.step)(
            jax.random.split(step_key, 8), state, actions, batch
        )
        return state, (reward, done, info["returned_episode_return"])

    _, (rewards, dones, returns) = jax.jit(
        lambda s: jax.lax.scan(one_step, s, jax.random.split(jax.random.key(2), 300))
    )(state)
    assert rewards.shape == (300, 8) and float(rewards.sum()) == 300 * 8  # CartPole: 1 per step
    finished = np.asarray(returns)[np.asarray(dones)]
    assert (
        finished.size > 8 and np.all(finished >= 1) and finished.sum() <= 300 * 8
    )  # random play falls


def test_without_gymnax_the_spaces_are_contextrls(monkeypatch):
    monkeypatch.setitem(sys.modules, "gymnax", None)  # what an environment without gymnax sees
    env, params = gymnax.make("CartPole")
    assert isinstance(env.observation_space(params), Box)
    assert isinstance(env.action_space(params), Discrete)


def test_registered_envs_is_a_list_of_ids_as_gymnax_has_it():
    """``for name in gymnax.registered_envs: gymnax.make(name)`` runs as it does on gymnax: a list
    with gymnax's ids where gymnax has the environment (the loop above makes each of them)."""
    assert isinstance(gymnax.registered_envs, list)
    shared = {"CartPole-v1", "Pendulum-v1", "Acrobot-v1", "MountainCar-v0"}
    assert shared | {"MountainCarContinuous-v0"} <= set(gymnax.registered_envs)
    assert "CartPole" not in gymnax.registered_envs  # one id per environment
    assert gymnax.registered_envs[:3] == [
        "CartPole-v1",
        "Pendulum-v1",
        "Acrobot-v1",
    ]  # gymnax's order


def test_gymnax_1_code_gets_six_values_from_v1_and_both_agree():
    """``import contextrl.gymnax.v1 as gymnax`` answers gymnax 1.0's step (terminated and truncated in
    place of done); the default face keeps 0.0.x's five. Same transitions, episode end by episode end."""
    import contextrl.gymnax.v1 as gymnax1

    five, params = gymnax.make("CartPole-v1", max_steps=30)
    six, _ = gymnax1.make("CartPole-v1", max_steps=30)
    assert gymnax1.registered_envs == gymnax.registered_envs
    obs5, state5 = five.reset(jax.random.key(0), params)
    _, state6 = six.reset(jax.random.key(0), params)
    ends = {"terminated": 0, "truncated": 0}
    for t in range(80):  # balancing (truncated at 30 steps), then pushing left (terminated)
        key, action = jax.random.key(t + 1), int(obs5[2] > 0) if t < 40 else 0
        obs5, state5, reward5, done, info5 = five.step(key, state5, action, params)
        obs6, state6, reward6, terminated, truncated, info6 = six.step(key, state6, action, params)
        np.testing.assert_array_equal(obs5, obs6)
        assert float(reward5) == float(reward6) and bool(done) == bool(terminated | truncated)
        assert bool(terminated) == bool(info5["terminated"]) and set(info6) == set(info5)
        ends["terminated"] += int(terminated)
        ends["truncated"] += int(truncated)
    assert ends["terminated"] > 0 and ends["truncated"] > 0  # both kinds of end were compared
    with pytest.raises(ValueError, match="step_api must be one of"):
        gymnax.make("CartPole-v1", step_api="2.0")
