"""Host vector envs: copies stepped in worker slices give what gymnasium's SyncVectorEnv of the same
single adapters gives, step by step (observations, rewards, flags, info with final_obs/final_info)."""

import functools
import logging

import gymnasium
import jax
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import contextrl as crl
from contextrl.context.features import ContextError
from contextrl.gymnasium import ContextualGymEnv, HostVectorEnv, host_vector, make_vector_env


def reference(env_id: str, num_envs: int, **kwargs) -> gymnasium.vector.SyncVectorEnv:
    """gymnasium's own vector env over the single adapters, copy i with its copy index."""
    factories = [
        functools.partial(ContextualGymEnv, env_id, copy_index=i, num_copies=num_envs, **kwargs)
        for i in range(num_envs)
    ]
    return gymnasium.vector.SyncVectorEnv(factories, autoreset_mode=AutoresetMode.SAME_STEP)


def assert_same(ours, theirs, where="") -> None:
    """Equal values, keys, masks and dtypes, through dicts and object arrays."""
    if isinstance(theirs, dict):
        assert set(ours) == set(theirs), (where, sorted(ours), sorted(theirs))
        for key in theirs:
            assert_same(ours[key], theirs[key], f"{where}/{key}")
    elif isinstance(theirs, np.ndarray) and theirs.dtype == object:
        assert isinstance(ours, np.ndarray) and ours.shape == theirs.shape, where
        for index, (a, b) in enumerate(zip(ours, theirs, strict=True)):
            assert_same(a, b, f"{where}[{index}]")
    else:
        np.testing.assert_array_equal(ours, theirs, err_msg=where)
        if isinstance(theirs, np.ndarray):
            assert ours.dtype == theirs.dtype, (where, ours.dtype, theirs.dtype)


def run_side_by_side(ours, theirs, actions, resets=()) -> int:
    """Step both with ``actions``; at step k in ``resets`` reset both with that (seed, options).
    Returns how many episodes ended."""
    for got, want in zip(ours.reset(seed=5), theirs.reset(seed=5), strict=True):
        assert_same(got, want, "reset")
    ended = 0
    for step, action in enumerate(actions):
        if step in resets:
            seed, options = resets[step]
            for got, want in zip(
                ours.reset(seed=seed, options=dict(options)),
                theirs.reset(seed=seed, options=dict(options)),
                strict=True,
            ):
                assert_same(got, want, f"reset at {step}")
        got, want = ours.step(action), theirs.step(action)
        for index, (a, b) in enumerate(zip(got, want, strict=True)):
            assert_same(a, b, f"step {step}, item {index}")
        ended += int(np.sum(want[2] | want[3]))
    return ended


@pytest.mark.parametrize("num_workers", [0, 2])  # every copy here; three slices
def test_slices_step_as_gymnasium_sync_vector_env_with_resampled_dict_observations(num_workers):
    count = 5
    options = dict(
        contexts={"GRAVITY_Y": crl.Uniform(-12.0, -2.0), "MAIN_ENGINE_POWER": 13.0},
        obs_context_features="all",
        obs_context_as_dict=True,
        max_steps=25,
    )
    ours = HostVectorEnv("LunarLander", count, num_workers=num_workers, **options)
    theirs = reference("LunarLander", count, **options)
    assert ours.single_observation_space == theirs.single_observation_space
    actions = np.random.default_rng(0).integers(0, 4, (90, count))
    partial = np.array([True, False, False, True, False])
    resets = {40: (None, {"reset_mask": partial}), 60: (9, {"context": {"GRAVITY_Y": -3.0}})}
    assert run_side_by_side(ours, theirs, actions, resets) >= 10  # auto-resets were compared
    ours.close()
    theirs.close()


def compilations(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if "Finished XLA compilation" in r.getMessage()]


def test_host_copies_of_one_configuration_compile_their_episode_start_once(caplog):
    """A host copy's episode start (context, start key, context observation) is one compiled call;
    copies with the same selection and context observation share the program (each copy compiled
    its own before), another configuration has its own."""

    def copy(index, features):
        env = ContextualGymEnv(
            "LunarLander",
            copy_index=index,
            num_copies=4,
            contexts={"GRAVITY_Y": crl.Uniform(-11.25, -8.75)},
            obs_context_features=features,
        )
        env.reset(seed=3)
        return env

    copy(0, "varying")
    caplog.clear()
    with jax.log_compiles(), caplog.at_level(logging.WARNING):
        for index in (1, 2, 3):
            copy(index, "varying")
    assert compilations(caplog) == []
    caplog.clear()
    with jax.log_compiles(), caplog.at_level(logging.WARNING):
        copy(0, "all")  # every feature visible: another context observation
    assert any("_start" in message for message in compilations(caplog))


def test_step_facts_and_set_contexts_match_with_a_worker():
    """RnaDesign reports facts at every step (dataset, target id): they arrive for every copy."""
    count = 3
    options = dict(
        contexts=[{"target_id_first": i, "target_id_last": i} for i in (1, 4)], max_steps=12
    )
    ours = HostVectorEnv("RnaDesign", count, num_workers=1, **options)
    theirs = reference("RnaDesign", count, **options)
    actions = np.random.default_rng(1).integers(0, 4, (40, count))
    assert run_side_by_side(ours, theirs, actions) >= 6
    assert ours.call("copy_index") == (0, 1, 2)
    ours.close()
    theirs.close()


def test_an_error_in_a_worker_is_raised_here_and_the_env_goes_on():
    envs = HostVectorEnv("LunarLander", 2, num_workers=1, contexts=[{"GRAVITY_Y": -4.0}])
    envs.reset(seed=0)
    with pytest.raises(ContextError, match="context_id"):
        envs.reset(options={"context_id": 7})
    obs, info = envs.reset(seed=0)
    np.testing.assert_array_equal(info["context_id"], [0, 0])
    with pytest.raises(ValueError, match="actions must be 2 integers in"):
        envs.step(np.array([0, 4]))
    assert envs.step(np.array([0, 1]))[0].shape == (2, 8)
    envs.close()


@pytest.mark.parametrize(
    "arguments, message",
    [
        ({"num_workers": 2}, r"num_workers must lie in \[0, num_envs - 1 = 1\]"),
        ({"num_workers": 1.5}, "num_workers must be an integer"),
        ({"vectorization": "sync", "num_workers": 2}, 'vectorization="sync" steps in this process'),
    ],
)
def test_worker_counts_are_checked_before_any_process_starts(arguments, message):
    with pytest.raises(ValueError, match=message):
        make_vector_env("LunarLander", num_envs=2, **arguments)


def test_jax_envs_refuse_a_worker_count():
    with pytest.raises(ValueError, match="num_workers is for host environments"):
        make_vector_env("CartPole", num_envs=2, num_workers=2)


def test_default_workers_use_every_core_while_each_slice_keeps_eight_copies(monkeypatch):
    monkeypatch.setattr(host_vector.os, "sched_getaffinity", lambda pid: {0, 1, 2, 3})
    counts = {copies: host_vector.default_workers(copies) for copies in (1, 8, 15, 16, 24, 64)}
    assert counts == {1: 0, 8: 0, 15: 0, 16: 1, 24: 2, 64: 3}


def test_the_host_collector_steps_alike_with_and_without_workers():
    """The agents' host collector on worker slices: the same steps, context input and curve row."""
    from contextrl.agents.host import HostCollector

    contexts = [{"GRAVITY_Y": g} for g in (-11.0, -7.0, -3.0)]
    collectors = [
        HostCollector("LunarLander", 16, contexts, "concat_all", seed=2, num_workers=workers)
        for workers in (0, 1)
    ]
    actions = np.random.default_rng(3).integers(0, 4, (120, 16))
    for action in actions:
        here, split = (collector.step(action) for collector in collectors)
        for name in ("reward", "terminated", "truncated", "final_obs", "obs", "context"):
            np.testing.assert_array_equal(getattr(split, name), getattr(here, name), err_msg=name)
    rows = [collector.close_period() for collector in collectors]
    assert rows[0]["episodes_finished"] > 0
    assert_same(rows[1], rows[0])
    for collector in collectors:
        collector.close()
