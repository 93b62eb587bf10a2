"""PPO: it learns CartPole, vmapped seeds and specialists match single runs, the context reaches the
network, bad configs fail before compilation, results evaluate, save and load."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import contextrl as crl
from contextrl.agents import (
    ConfigError,
    checkpoint_info,
    evaluate,
    load_checkpoint,
    ppo,
    save_checkpoint,
)
from tests.helpers import learning

TINY = dict(total_timesteps=256, num_envs=4, num_steps=16, num_minibatches=2, update_epochs=2)
TINY_NET = dict(hidden_sizes=(16,))


@pytest.fixture(scope="module")
def cartpole():
    return crl.make("CartPole")


def test_ppo_learns_cartpole():
    """PPO, 100k steps (8 copies × 128 steps, lr 2.5e-3), seeds 0–3 in one vmapped call.

    Measured (tests/helpers/margins.py), the deterministic policy's mean return over 10 episodes:
    default numerics, seeds 0–15: min 266, median 500, 4 of 16 below 400; fast math, seeds 100–107:
    min 336, median 500. So "every seed reaches 475" fails by luck (one seed in three misses it);
    what holds with a margin: every seed >= 150 (a random policy scores about 22) and the median
    of the four >= 250 (the worst four measured seeds give 307). The first updates stay below 100
    (measured 38–59), so the return was learned.
    """
    statistics = learning.ppo_cartpole(range(4))
    returns = statistics["return"]
    assert np.all(returns >= 150) and np.median(returns) >= 250, returns
    assert np.all(statistics["first_updates"] < 100), statistics["first_updates"]


@pytest.fixture(scope="module")
def shared(cartpole):
    """One tiny concat_varying agent compiled twice (alone; vmapped over 2 agents) for many tests."""
    contexts = crl.sample(cartpole, {"length": crl.Uniform(0.05, 0.3)}, 3, jax.random.key(2))
    config = ppo.PPOConfig(
        **{**TINY, "total_timesteps": 1024},
        **TINY_NET,
        variant="concat_varying",
        episode_log_size=5000,
    )
    train = ppo.make_train(config, cartpole, contexts)
    return config, contexts, jax.jit(train), jax.jit(jax.vmap(train))


def _leaves_close(a, b):
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-4, atol=1e-5)


def test_vmapped_seeds_equal_single_runs(shared):
    _, contexts, train, train_many = shared
    keys = jax.random.split(jax.random.key(3), 2)
    together = train_many(keys, jax.tree_util.tree_map(lambda x: jnp.stack([x] * 2), contexts))
    for i in range(2):
        alone = train(keys[i], contexts)
        _leaves_close(alone.params, jax.tree_util.tree_map(lambda x, i=i: x[i], together.params))
        np.testing.assert_array_equal(
            alone.metrics["episodes"]["length"], together.metrics["episodes"]["length"][i]
        )
    # Different seeds really differ.
    kernels = together.params["actor"]["out"]["kernel"]
    assert not np.allclose(kernels[0], kernels[1])


def test_vmapped_specialists_each_train_on_their_own_set(cartpole, shared):
    """One agent per context set: the episodes of agent i come from set i, as if trained alone."""
    _, _, train, train_many = shared
    short = crl.sample(cartpole, {"length": crl.Uniform(0.05, 0.06)}, 3, jax.random.key(4))
    long = crl.sample(cartpole, {"length": crl.Uniform(2.0, 2.5)}, 3, jax.random.key(4))
    sets = cartpole.context_space.stack([short, long])  # (2 agents, 3 contexts)
    keys = jax.random.split(jax.random.key(4), 2)
    specialists = train_many(keys, sets)
    lengths = np.asarray(specialists.metrics["episodes"]["length"])
    finished = np.asarray(specialists.metrics["episodes"]["context_id"]) >= 0
    # A short pole falls much sooner than a long one under the same (near-random) policy.
    assert lengths[0][finished[0]].mean() * 2 < lengths[1][finished[1]].mean()
    alone = train(keys[1], long)
    _leaves_close(alone.params, jax.tree_util.tree_map(lambda x: x[1], specialists.params))


def test_episode_log_matches_the_rollout(shared):
    """CartPole pays 1 per step, so each logged return equals its length; ids come from the set."""
    config, contexts, train, _ = shared
    result = train(jax.random.key(8), contexts)
    episodes = {k: np.asarray(v) for k, v in result.metrics["episodes"].items()}
    total = int(episodes["total"])
    assert total > 10
    valid = episodes["context_id"] >= 0
    assert valid.sum() == total
    np.testing.assert_array_equal(episodes["return"][valid], episodes["length"][valid])
    assert set(episodes["context_id"][valid]) <= {0, 1, 2}
    assert episodes["length"][valid].sum() <= config.total_timesteps
    assert np.all(np.diff(episodes["step"][valid]) >= 0)
    assert int(np.asarray(result.metrics["episodes_finished"]).sum()) == total
    per_context = np.asarray(result.metrics["context_return"])
    assert per_context.shape == (config.num_updates, 3)
    # Per-context means agree with the individual episodes of the last update.
    last = episodes["step"] > config.total_timesteps - config.num_envs * config.num_steps
    for context_id in range(3):
        chosen = valid & last & (episodes["context_id"] == context_id)
        if chosen.any():
            assert per_context[-1, context_id] == pytest.approx(episodes["return"][chosen].mean())


def test_concat_varying_sees_only_the_varying_feature(cartpole, shared):
    """Same state, different pole length: the action probabilities differ; gravity is no input."""
    config, contexts, train, _ = shared
    params = train(jax.random.key(6), contexts).params
    distribution = ppo.action_distribution(config, cartpole, contexts)
    obs = jnp.array([0.01, 0.2, -0.03, -0.1])
    a = distribution(params, obs, cartpole.context(length=0.1))
    b = distribution(params, obs, cartpole.context(length=4.0))
    assert not np.allclose(a, b, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(
        a, distribution(params, obs, cartpole.context(length=0.1, gravity=20.0))
    )


@pytest.mark.parametrize(("mode", "differs"), [("concat_all", True), ("hidden", False)])
def test_context_reaches_the_network(cartpole, mode, differs):
    """Freshly initialised agents: concat_all reacts to any feature, hidden to none."""
    config = ppo.PPOConfig(**TINY, **TINY_NET, variant=mode)
    context = cartpole.default_context()
    params = ppo.init_params(config, cartpole, context, jax.random.key(5))
    distribution = ppo.action_distribution(config, cartpole, context)
    obs = jnp.array([0.01, 0.2, -0.03, -0.1])
    for change in (dict(length=4.0), dict(gravity=50.0), dict(masscart=5.0)):
        a = distribution(params, obs, context)
        b = distribution(params, obs, cartpole.context(**change))
        assert (not np.allclose(a, b, rtol=0, atol=1e-6)) == differs, change


def test_gated_agent_learns_a_context_gate(cartpole):
    """The gate starts neutral (as a hidden agent) and becomes context-dependent through training."""
    contexts = crl.sample(cartpole, {"length": crl.Uniform(0.1, 4.0)}, 8, jax.random.key(5))
    config = ppo.PPOConfig(**TINY, **TINY_NET, variant="gated", learning_rate=1e-2)
    distribution = ppo.action_distribution(config, cartpole, contexts)
    obs = jnp.array([0.01, 0.2, -0.03, -0.1])
    short, long = cartpole.context(length=0.1), cartpole.context(length=4.0)
    initial = ppo.init_params(config, cartpole, contexts, jax.random.key(6))
    np.testing.assert_array_equal(
        distribution(initial, obs, short), distribution(initial, obs, long)
    )
    params = jax.jit(ppo.make_train(config, cartpole, contexts))(jax.random.key(6)).params
    assert np.abs(np.asarray(params["actor"]["gate"]["kernel"])).max() > 0
    a, b = distribution(params, obs, short), distribution(params, obs, long)
    assert not np.allclose(a, b, rtol=0, atol=1e-6)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (dict(learning_rate=-1e-3), "learning_rate must be > 0"),
        (dict(learning_rate=float("nan")), "learning_rate must be finite"),
        (dict(num_envs=0), "num_envs must be > 0"),
        (dict(num_envs=2.5), "num_envs must be an integer"),
        (dict(variant="visible"), "variant: unknown 'visible'; choose one of"),
        (dict(gamma=1.5), "gamma must be in [0, 1]"),
        (dict(num_minibatches=3), "num_minibatches (3) must divide"),
        (dict(total_timesteps=10), "less than one rollout"),
        (dict(hidden_sizes=(64, 0)), "hidden_sizes"),
        (dict(activation="gelu"), "activation: unknown 'gelu'"),
        (dict(context_selector="best"), "unknown context selector 'best'"),
        (dict(clip_value="no"), "clip_value must be True or False, got 'no'"),
    ],
)
def test_bad_config_fails_before_compilation(cartpole, change, message):
    config = ppo.PPOConfig(**{**TINY, **change})
    with pytest.raises(ValueError) as error:
        ppo.make_train(config, cartpole, cartpole.default_context())
    assert message in str(error.value)


def test_value_clipping_changes_the_critic_update_and_can_be_turned_off(cartpole):
    """At a step size where a minibatch moves the value by more than clip_eps, the clipped value
    loss trains another critic than the plain squared error does."""
    changed = dict(TINY, **TINY_NET, learning_rate=1e-2, anneal_lr=False)

    def trained(clip_value):
        config = ppo.PPOConfig(**changed, clip_value=clip_value)
        return ppo.make_train(config, cartpole, cartpole.default_context())(
            jax.random.key(3)
        ).params

    clipped, plain = trained(True), trained(False)
    critic_gap = jax.tree_util.tree_map(lambda a, b: float(jnp.abs(a - b).max()), clipped, plain)
    assert max(jax.tree_util.tree_leaves(critic_gap["critic"])) > 1e-3


def test_observation_mode_the_env_cannot_give(cartpole):
    config = ppo.PPOConfig(**TINY, variant="concat_varying")
    with pytest.raises(ConfigError, match="no context feature varies"):
        ppo.make_train(config, cartpole, cartpole.default_context())
    with pytest.raises(ConfigError, match="already appends"):
        ppo.make_train(
            ppo.PPOConfig(**TINY),
            cartpole.with_obs_context("all"),
            cartpole.default_context(),
        )
    train = ppo.make_train(ppo.PPOConfig(**TINY), cartpole, {"length": crl.Uniform(0.25, 0.75)})
    with pytest.raises(ConfigError, match="distribution spec"):
        train(jax.random.key(0), cartpole.context_space.stack([cartpole.default_context()]))


def test_continuous_actions_resampled_contexts_and_progress(capsys):
    """A Gaussian policy on Pendulum with masses resampled at each reset (id −1), progress printed."""
    env = crl.make("Pendulum")
    config = ppo.PPOConfig(**TINY, **TINY_NET, variant="concat_varying", progress_every=2)
    spec = {"m": crl.Uniform(0.5, 1.5)}
    result = jax.jit(ppo.make_train(config, env, spec))(jax.random.key(11))
    jax.effects_barrier()
    assert result.params["log_std"].shape == (1,)
    ids = np.asarray(result.metrics["episodes"]["context_id"])
    assert set(ids[ids != -2]) <= {-1}
    policy = ppo.make_policy(config, env, spec)
    obs = jnp.array([1.0, 0.0, 1e4])  # an extreme velocity pushes the mean beyond the bound
    action = policy(result.params, obs, env.default_context(), jax.random.key(0))
    assert action.shape == (1,)
    assert np.all(np.abs(np.asarray(action)) <= 2.0)
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("[PPO]")]
    assert len(lines) == config.num_updates // 2
    assert "steps/s" in lines[0] and "recent return" in lines[0]
    assert f"step        128/{config.num_updates * 64:,}" in lines[0]


def test_checkpoint_round_trip(cartpole, shared, tmp_path):
    config, contexts, train, _ = shared
    params = train(jax.random.key(12), contexts).params
    path = save_checkpoint(tmp_path / "agent", params, config, env="CartPole", seed=12)
    assert path.name == "agent.npz"
    assert [p.name for p in tmp_path.iterdir()] == ["agent.npz"]  # no temporary file left behind
    loaded = load_checkpoint(path)
    info = checkpoint_info(path)
    assert info["metadata"] == {"env": "CartPole", "seed": 12}
    restored_config = ppo.PPOConfig(**info["config"])
    assert restored_config == config
    policy = ppo.make_policy(restored_config, cartpole, contexts)
    key = jax.random.key(13)
    np.testing.assert_array_equal(
        evaluate(policy, params, cartpole, contexts, 3, key),
        evaluate(policy, loaded, cartpole, contexts, 3, key),
    )


def test_ppo_through_the_gymnasium_vector_adapter(cartpole):
    """The host path: CartPole stepped through gymnasium's vector API, two pole lengths visible.

    Budget: 8 updates of 4 × 64 steps. Episodes are logged with the set's ids, and returns equal
    lengths; the policy acts on the context read from ``info["context"]``.
    """
    contexts = cartpole.context_space.stack(
        [cartpole.context(length=0.1), cartpole.context(length=2.0)]
    )
    config = ppo.PPOConfig(
        total_timesteps=2048, num_envs=4, num_steps=64, **TINY_NET, variant="concat_varying"
    )
    result = ppo.train_gymnasium(config, "CartPole", contexts, jax.random.key(0), seed=3)
    episodes = result.metrics["episodes"]
    assert episodes["total"] > 10
    np.testing.assert_array_equal(episodes["return"], episodes["length"])
    ids = episodes["context_id"]
    assert set(ids) == {0, 1}
    # The short pole (id 0) falls much sooner than the long one (id 1).
    assert episodes["length"][ids == 0].mean() * 2 < episodes["length"][ids == 1].mean()
    assert result.metrics["step"][-1] == 2048
    distribution = ppo.action_distribution(config, cartpole, contexts)
    obs = jnp.array([0.01, 0.2, -0.03, -0.1])
    assert not np.allclose(
        distribution(result.params, obs, contexts[0]),
        distribution(result.params, obs, contexts[1]),
        rtol=0,
        atol=1e-6,
    )
