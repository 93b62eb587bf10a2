"""The CARL face: CARL's documented examples run with only the import changed, and behave correctly.

Each example below is CARL 1.1.1 code as its documentation and docstrings show it; ``run_carl`` swaps
``from carl.`` for ``from contextrl.carl.`` and nothing else.
"""

import importlib
import os
import subprocess
import sys

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import contextrl as crl
from contextrl.carl.envs import CARLCartPole, CARLPendulum
from contextrl.gymnasium import ContextualGymEnv

CLASSIC_CONTROL = [
    "CARLAcrobot",
    "CARLCartPole",
    "CARLMountainCar",
    "CARLMountainCarContinuous",
    "CARLPendulum",
]


def run_carl(code: str) -> dict:
    """Run CARL code with the import changed to this face; return its variables."""
    namespace: dict = {}
    exec(code.replace("from carl.", "from contextrl.carl."), namespace)
    return namespace


SAMPLER_EXAMPLE = """
from carl.envs import CARLCartPole
from carl.context.context_space import NormalFloatContextFeature, UniformFloatContextFeature
from carl.context.sampler import ContextSampler

context_distributions = [
    NormalFloatContextFeature("gravity", mu=9.8, sigma=1),
    UniformFloatContextFeature("length", lower=0.25, upper=1.0),
]
context_sampler = ContextSampler(
    context_distributions=context_distributions,
    context_space=CARLCartPole.get_context_space(),
    seed=42,
)
contexts = context_sampler.sample_contexts(n_contexts=5)
env = CARLCartPole(contexts=contexts)
state, info = env.reset(seed=0)
"""

SELECTOR_EXAMPLE = """
from carl.envs import CARLCartPole
from carl.context.selection import StaticSelector

contexts = {0: {"length": 0.4}, 1: {"length": 0.9}}
env = CARLCartPole(contexts=contexts, context_selector=StaticSelector)
ids = []
for _ in range(3):
    env.reset()
    ids.append(env.context_id)
"""

CUSTOM_SELECTOR_EXAMPLE = """
from carl.envs import CARLCartPole
from carl.context.selection import AbstractSelector, CustomSelector

def selector_function(inst: AbstractSelector):
    if inst.n_calls == 0:
        context_id = 1
    else:
        context_id = 0
    return inst.contexts[inst.contexts_keys[context_id]], context_id

contexts = {0: {"gravity": 5.0}, 1: {"gravity": 15.0}}
selector = CustomSelector(contexts=contexts, selector_function=selector_function)
env = CARLCartPole(contexts=contexts, context_selector=selector)
ids = []
for _ in range(3):
    env.reset()
    ids.append(env.context_id)
"""

VECTOR_OBS_EXAMPLE = """
from carl.envs import CARLPendulum

env = CARLPendulum(
    contexts={0: {"l": 1.5}},
    obs_context_features=["l", "m"],
    obs_context_as_dict=False,
)
state, info = env.reset(seed=1)
"""

DEFAULTS_EXAMPLE = """
from carl.envs import CARLCartPole

default_context = CARLCartPole.get_default_context()
features = CARLCartPole.get_context_features()
space = CARLCartPole.get_context_space()
"""


def rollout(env, seed: int, steps: int, actions=None):
    """Observations (base part) of one seeded run with fixed actions, resetting finished episodes."""
    obs, _ = env.reset(seed=seed)
    actions = np.random.default_rng(seed).integers(0, 2, steps) if actions is None else actions
    out = [obs["obs"]]
    for action in actions:
        obs, _, terminated, truncated, _ = env.step(int(action))
        out.append(obs["obs"])
        if terminated or truncated:
            obs, _ = env.reset()
    return np.array(out)


def test_sampler_example_gives_seeded_valid_contexts_and_a_dict_observation():
    ns = run_carl(SAMPLER_EXAMPLE)
    contexts, env, state = ns["contexts"], ns["env"], ns["state"]
    assert list(contexts) == [0, 1, 2, 3, 4]
    gravities = [c["gravity"] for c in contexts.values()]
    lengths = [c["length"] for c in contexts.values()]
    assert len(set(gravities)) == 5 and all(0.1 <= g <= 100 for g in gravities)
    assert all(0.25 <= x <= 1.0 for x in lengths)
    assert all(c["masscart"] == 1.0 for c in contexts.values())  # unlisted features keep defaults
    assert run_carl(SAMPLER_EXAMPLE)["contexts"] == contexts  # same seed, same contexts
    assert set(state) == {"obs", "context"} and env.observation_space.contains(state)
    assert state["context"]["gravity"] == np.float32(gravities[0])
    assert ns["info"]["context_id"] == env.context_id == 0
    seen = []
    for _ in range(6):
        _, info = env.reset()
        seen.append(info["context_id"])
    assert seen == [1, 2, 3, 4, 0, 1]  # round robin by default
    assert env.context == env.contexts[1] and env.context_selector.context_id == 1


def test_sampler_draws_differ_by_seed_and_by_call():
    space = CARLCartPole.get_context_space()
    from contextrl.carl.context.context_space import UniformFloatContextFeature
    from contextrl.carl.context.sampler import ContextSampler

    def sampler(seed):
        return ContextSampler([UniformFloatContextFeature("tau", 0.01, 0.05)], space, seed=seed)

    first = sampler(0)
    a, b = first.sample_contexts(3), first.sample_contexts(3)
    assert a != b  # a second call draws new contexts
    assert sampler(0).sample_contexts(3) == a and sampler(1).sample_contexts(3) != a


def test_static_selector_keeps_the_first_context():
    assert run_carl(SELECTOR_EXAMPLE)["ids"] == [0, 0, 0]


def test_custom_selector_function_is_called_at_every_reset():
    ns = run_carl(CUSTOM_SELECTOR_EXAMPLE)
    assert ns["ids"] == [1, 0, 0]
    assert ns["env"].step(0)[4]["context_id"] == 0
    assert ns["env"].context["gravity"] == 5.0 and ns["selector"].n_calls == 3


def test_vector_context_observation_lies_in_its_space():
    ns = run_carl(VECTOR_OBS_EXAMPLE)
    state, env = ns["state"], ns["env"]
    np.testing.assert_allclose(state["context"], [1.5, 1.0])
    assert state["context"].dtype == np.float32 and env.observation_space.contains(state)
    assert isinstance(env.observation_space["context"], gymnasium.spaces.Box)


def test_defaults_and_features_come_from_the_declarations():
    ns = run_carl(DEFAULTS_EXAMPLE)
    default = ns["default_context"]
    declared = crl.make("CartPole").context_space
    assert list(default) == list(declared.names)
    assert default["initial_state_lower"] == -0.05  # gymnasium's start range (CARL says -0.1)
    gravity = ns["features"]["gravity"]
    assert (gravity.lower, gravity.upper, gravity.default_value) == (0.1, 100.0, 9.8)
    space = ns["space"]
    samples = space.sample_contexts(size=50)
    for name in space.context_feature_names:  # CARL draws inf/NaN for its infinite bounds
        low, high = space.get_lower_and_upper_bound(name)
        values = np.array([s[name] for s in samples])
        assert np.all(np.isfinite(values)) and np.all((values >= low) & (values <= high))
    assert space.sample_contexts(["length"], size=2, seed=3) == space.sample_contexts(
        ["length"], size=2, seed=3
    )
    assert space.verify_context({"length": 1.0}) and not space.verify_context({"length": 50.0})
    assert not space.verify_context({"lenght": 1.0})
    assert space.insert_defaults({"length": 1.0})["gravity"] == 9.8


def test_masscart_acts():
    """CARL caches the total mass at construction, so its masscart changes nothing."""
    from contextrl.carl.context.selection import StaticSelector

    env = CARLCartPole(
        contexts={0: {"masscart": 0.5}, 1: {"masscart": 5.0}}, context_selector=StaticSelector
    )
    light = rollout(env, seed=0, steps=20)
    env.context_id = 1  # with a static selector: every later episode
    heavy = rollout(env, seed=0, steps=20)
    assert env.context_id == 1 and env.context["masscart"] == 5.0
    np.testing.assert_array_equal(light[0], heavy[0])  # same start state from the same seed
    assert not np.allclose(light[1:], heavy[1:])


def test_same_trajectory_as_the_gymnasium_environment():
    """The face runs the one stepping path: same contexts and seed, same observations."""
    contexts = {0: {"length": 0.3}, 1: {"length": 1.2}}
    ours = rollout(CARLCartPole(contexts=contexts), seed=5, steps=120)
    plain = ContextualGymEnv("CartPole", contexts=contexts, obs_context_features="all")
    obs, _ = plain.reset(seed=5)
    expected = [obs[:4]]
    for action in np.random.default_rng(5).integers(0, 2, 120):
        obs, _, terminated, truncated, _ = plain.step(int(action))
        expected.append(obs[:4])
        if terminated or truncated:
            obs, _ = plain.reset()
    np.testing.assert_array_equal(ours, np.array(expected))


def test_seeds_are_honoured_by_start_states_and_the_random_selector():
    from contextrl.carl.context.selection import RandomSelector

    contexts = {i: {"length": 0.2 + 0.2 * i} for i in range(5)}

    def ids(seed):
        env = CARLCartPole(contexts=contexts, context_selector=RandomSelector)
        env.reset(seed=seed)
        return [env.context_id] + [env.reset()[1]["context_id"] for _ in range(15)]

    assert ids(3) == ids(3) and ids(3) != ids(4)
    assert len(set(ids(3))) >= 3
    a, b = CARLCartPole(), CARLCartPole()
    np.testing.assert_array_equal(rollout(a, 7, 30), rollout(b, 7, 30))
    assert not np.array_equal(rollout(a, 7, 30), rollout(b, 8, 30))


def test_ids_are_the_keys_of_the_mapping():
    env = CARLCartPole(contexts={"short": {"length": 0.2}, "long": {"length": 2.0}})
    _, info = env.reset(seed=0)
    assert info["context_id"] == env.context_id == "short"
    assert env.context_selector.context_key == "short"  # CARL answers None for the first context
    env.reset()
    assert env.context_id == "long" and env.context["length"] == 2.0
    env.context_id = "short"
    env.reset()
    assert env.context_id == "short"


def test_contexts_can_be_replaced():
    env = CARLCartPole(contexts={0: {"length": 0.3}})
    env.contexts = {7: {"length": 1.7}}
    _, info = env.reset(seed=0)
    assert info["context_id"] == 7 and env.context["length"] == 1.7
    assert env.contexts[7]["gravity"] == 9.8


def test_hidden_context_gives_an_empty_context_part():
    env = CARLCartPole(obs_context_features=[])
    obs, _ = env.reset(seed=0)
    assert obs["context"] == {} and obs["obs"].shape == (4,)
    assert env.observation_space.contains(obs)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"contexts": {0: {"lenght": 0.5}}}, "unknown context feature 'lenght'"),
        (
            {"contexts": {0: {"length": 50.0}}},
            r"length: value 50 is outside its bounds \[0.05, 5\]",
        ),
        ({"contexts": {0: {"length": float("nan")}}}, "not finite"),
        ({"contexts": [{"length": 0.5}]}, "mapping id -> dict"),
        ({"context_selector": "random"}, "context_selector must be"),
        ({"obs_context_features": ["mass"]}, "valid features"),
        ({"obs_context_as_dict": "yes"}, "True or False"),
    ],
)
def test_bad_input_is_refused_with_a_clear_error(kwargs, message):
    with pytest.raises(crl.ContextError, match=message):
        CARLCartPole(**kwargs)


def test_bad_sampler_and_env_arguments_are_refused():
    from contextrl.carl.context.context_space import UniformFloatContextFeature
    from contextrl.carl.context.sampler import ContextSampler

    space = CARLCartPole.get_context_space()
    with pytest.raises(crl.ContextError, match="outside the feature's bounds"):
        ContextSampler([UniformFloatContextFeature("length", 0.1, 9.0)], space, seed=0)
    with pytest.raises(crl.ContextError, match="seed must be an integer"):
        ContextSampler([UniformFloatContextFeature("length", 0.1, 1.0)], space, seed=None)
    with pytest.raises(TypeError, match="contextrl environment"):
        CARLCartPole(env=gymnasium.make("CartPole-v1"))
    with pytest.raises(TypeError, match="runs CartPole"):
        CARLCartPole(env=crl.make("Pendulum"))
    with pytest.raises(crl.ContextError, match="not an id of the context set"):
        CARLCartPole().context_id = 3


def test_env_argument_takes_a_contextrl_environment():
    env = CARLCartPole(env=crl.make("CartPole", max_steps=3))
    env.reset(seed=0)
    truncated = [env.step(0)[3] for _ in range(3)]
    assert truncated == [False, False, True]


def test_every_carl_name_and_module_path_exists():
    import contextrl.carl.envs as envs

    for env_id in crl.registered():
        for alias in crl.spec(env_id).aliases:
            if alias.startswith("CARL"):
                cls = getattr(envs, alias)
                assert cls.env_id == env_id and alias in envs.__all__
    for module in ("carl_acrobot", "carl_cartpole", "carl_mountaincar", "carl_pendulum"):
        importlib.import_module(f"contextrl.carl.envs.gymnasium.classic_control.{module}")
    families = [("gymnasium", "classic_control"), ("gymnasium.box2d", "box2d"), ("dmc", "dmc")]
    for path, family in [*families, ("rna", "rna")]:
        module = importlib.import_module(f"contextrl.carl.envs.{path}")
        for name in envs.carl_names(family):
            assert getattr(module, name) is getattr(envs, name) and name in module.__all__
    from contextrl.carl.envs.gymnasium.classic_control.carl_pendulum import CARLPendulum as Same
    from contextrl.carl.utils.types import Contexts  # noqa: F401

    assert Same is CARLPendulum
    with pytest.raises(AttributeError, match="no CARL environment"):
        envs.CARLNoSuchEnv  # noqa: B018


def test_dmc_environment_through_the_face():
    pytest.importorskip("dm_control")
    from contextrl.carl.envs.dmc import CARLDmcPointMassEnv

    env = CARLDmcPointMassEnv(
        contexts={0: {"actuator_strength": 0.5}}, obs_context_features=["actuator_strength"]
    )
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs) and info["context_id"] == 0
    assert obs["context"]["actuator_strength"] == np.float32(0.5)
    obs, reward, *_ = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs) and np.isfinite(reward)


@pytest.mark.parametrize("name", CLASSIC_CONTROL)
def test_gymnasium_checker_passes_for_every_classic_control_class(name):
    import contextrl.carl.envs as envs
    from contextrl.carl.context.selection import RandomSelector

    cls = getattr(envs, name)
    env = cls(contexts={0: {}, 1: {}}, context_selector=RandomSelector)
    check_env(env, skip_render_check=False)
    check_env(cls(obs_context_features=[], obs_context_as_dict=False), skip_render_check=True)


def test_selector_subclass_and_selector_kwargs():
    from contextrl.carl.context.selection import AbstractSelector, CustomSelector

    class LastFirst(AbstractSelector):
        def _select(self):
            position = len(self.contexts) - 1 - self.n_calls % len(self.contexts)
            return self.contexts[self.contexts_keys[position]], position

    contexts = {"a": {"length": 0.3}, "b": {"length": 0.6}, "c": {"length": 0.9}}
    env = CARLCartPole(contexts=contexts, context_selector=LastFirst)
    assert [env.reset(seed=0)[1]["context_id"]] + [
        env.reset()[1]["context_id"] for _ in range(3)
    ] == ["c", "b", "a", "c"]

    def always_b(selector):
        return selector.contexts["b"], 1

    env = CARLCartPole(
        contexts=contexts,
        context_selector=CustomSelector,
        context_selector_kwargs={"selector_function": always_b},
    )
    env.reset(seed=0)
    assert env.context_id == "b" and env.context["length"] == 0.6


def test_context_part_is_fixed_per_episode_unless_noisy():
    contexts = {0: {"length": 0.3}, 1: {"length": 1.2}}
    env = CARLCartPole(contexts=contexts, obs_context_features=["length"])
    first, _ = env.reset(seed=0)
    after = env.step(0)[0]
    assert first["context"]["length"] == after["context"]["length"] == np.float32(0.3)
    assert env.reset()[0]["context"]["length"] == np.float32(1.2)
    assert first["context"]["length"] == np.float32(0.3)  # an earlier observation is untouched
    noisy = CARLCartPole(contexts=contexts, obs_context_features=["length"], obs_context_noise=0.2)
    values = {float(noisy.reset(seed=0)[0]["context"]["length"][0])}
    values |= {float(noisy.step(0)[0]["context"]["length"][0]) for _ in range(5)}
    assert len(values) == 6 and all(0.05 <= v <= 5.0 for v in values)


CUSTOM_ENV_EXAMPLE = """
from carl.envs.carl_env import CARLEnv
from carl.context.context_space import (
    CategoricalContextFeature,
    ContextSpace,
    NormalFloatContextFeature,
    UniformFloatContextFeature,
    UniformIntegerContextFeature,
)
from carl.context.sampler import ContextSampler


class CARLMyEnv(CARLEnv):
    @staticmethod
    def get_context_features():
        return {
            "gravity": UniformFloatContextFeature("gravity", lower=1.0, upper=20.0, default_value=9.8),
            "friction": NormalFloatContextFeature(
                "friction", mu=0.5, sigma=0.1, lower=0.0, upper=1.0, default_value=0.5
            ),
            "n_legs": UniformIntegerContextFeature("n_legs", lower=2, upper=8, default_value=4),
            "terrain": CategoricalContextFeature("terrain", choices=["flat", "hills"], default_value="flat"),
        }


space = CARLMyEnv.get_context_space()
direct = ContextSpace(CARLMyEnv.get_context_features())
sampler = ContextSampler(
    context_distributions=[NormalFloatContextFeature("gravity", mu=9.8, sigma=1.0)],
    context_space=space,
    seed=42,
)
contexts = sampler.sample_contexts(n_contexts=5)
"""


def test_a_users_own_env_declares_its_context_space_from_carl_features():
    namespace = run_carl(CUSTOM_ENV_EXAMPLE)
    space, direct = namespace["space"], namespace["direct"]
    defaults = {"gravity": 9.8, "friction": 0.5, "n_legs": 4, "terrain": "flat"}
    for each in (space, direct):
        assert each.context_feature_names == ["gravity", "friction", "n_legs", "terrain"]
        assert each.get_default_context() == defaults
        assert each.insert_defaults({"gravity": 3.0}) == {**defaults, "gravity": 3.0}
        assert each.insert_defaults({"gravity": 3.0}, ["n_legs"]) == {"n_legs": 4, "gravity": 3.0}
        assert each.verify_context({"gravity": 3.0, "n_legs": 6})
        assert not each.verify_context({"gravity": 30.0})
        assert not each.verify_context({"mass": 1.0})
        assert each.get_lower_and_upper_bound("gravity") == (1.0, 20.0)
        assert each.get_lower_and_upper_bound("n_legs") == (2, 8)
    box = space.to_gymnasium_space(["gravity", "n_legs"])
    np.testing.assert_array_equal(box.low, [1.0, 2.0])
    np.testing.assert_array_equal(box.high, [20.0, 8.0])
    assert set(space.to_gymnasium_space(as_dict=True).spaces) == set(defaults)
    contexts = namespace["contexts"]
    assert list(contexts) == [0, 1, 2, 3, 4]
    assert len({c["gravity"] for c in contexts.values()}) == 5
    for context in contexts.values():
        assert {k: v for k, v in context.items() if k != "gravity"} == {
            k: v for k, v in defaults.items() if k != "gravity"
        }
        assert 1.0 <= context["gravity"] <= 20.0 and space.verify_context(context)
    drawn = space.sample_contexts(size=50, seed=3)
    assert {c["terrain"] for c in drawn} == {"flat", "hills"}
    assert {c["n_legs"] for c in drawn} <= set(range(2, 9)) and len(
        {c["n_legs"] for c in drawn}
    ) > 3
    assert all(isinstance(c["n_legs"], int) for c in drawn)
    frictions = np.array([c["friction"] for c in drawn])  # the declared normal, not the whole range
    assert abs(frictions.mean() - 0.5) < 0.05 and frictions.std() < 0.15


def test_declared_features_take_carls_defaults_and_refuse_what_cannot_be_a_space():
    from contextrl.carl.context.context_space import (
        CategoricalContextFeature,
        ContextSpace,
        NormalFloatContextFeature,
        UniformFloatContextFeature,
        UniformIntegerContextFeature,
    )

    space = ContextSpace(
        {
            "a": UniformFloatContextFeature("a", lower=1.0, upper=3.0),
            "b": UniformFloatContextFeature("b", lower=1.0, upper=100.0, log=True),
            "c": UniformIntegerContextFeature("c", lower=1, upper=4),
            "d": NormalFloatContextFeature("d", mu=0.2, sigma=1.0, lower=-1.0, upper=1.0),
            "e": CategoricalContextFeature("e", choices=["x", "y"], weights=[0.2, 0.8]),
        }
    )
    assert space.get_default_context() == {"a": 2.0, "b": 10.0, "c": 2, "d": 0.2, "e": "y"}
    with pytest.raises(crl.ContextError, match="g: give a default_value"):
        ContextSpace({"g": UniformFloatContextFeature("g", lower=1.0, upper=np.inf)})
    with pytest.raises(crl.ContextError, match="g: upper is NaN"):
        ContextSpace({"g": UniformFloatContextFeature("g", lower=1.0, upper=np.nan)})
    with pytest.raises(crl.ContextError, match="g: default"):
        ContextSpace(
            {"g": UniformFloatContextFeature("g", lower=1.0, upper=2.0, default_value=5.0)}
        )
    with pytest.raises(crl.ContextError, match="names the feature"):
        ContextSpace({"g": UniformFloatContextFeature("gravity", lower=1.0, upper=2.0)})


def test_infinite_bounds_are_declared_and_checked_but_never_drawn_uniformly():
    from contextrl.carl.context.context_space import (
        ContextSpace,
        NormalFloatContextFeature,
        UniformFloatContextFeature,
    )
    from contextrl.carl.context.sampler import ContextSampler

    space = ContextSpace(
        {
            "gravity": UniformFloatContextFeature(
                "gravity", lower=0.1, upper=np.inf, default_value=9.8
            ),
            "friction": NormalFloatContextFeature("friction", mu=0.5, sigma=0.1),  # unbounded
        }
    )
    assert space.get_lower_and_upper_bound("gravity") == (0.1, np.inf)
    assert space.get_lower_and_upper_bound("friction") == (-np.inf, np.inf)
    box = space.to_gymnasium_space()
    np.testing.assert_array_equal(box.low, np.float32([0.1, -np.inf]))
    np.testing.assert_array_equal(box.high, [np.inf, np.inf])
    assert space.verify_context({"gravity": 1e30}) and not space.verify_context({"gravity": np.inf})
    assert not space.verify_context({"gravity": 0.0})
    with pytest.raises(crl.ContextError, match=r"gravity: cannot draw uniformly from \[0.1, inf\]"):
        space.sample_contexts(["gravity"])
    drawn = ContextSampler(
        [NormalFloatContextFeature("gravity", mu=9.8, sigma=1.0)], space, seed=0
    ).sample_contexts(200)
    gravity = np.array([c["gravity"] for c in drawn.values()])
    assert abs(gravity.mean() - 9.8) < 0.3 and gravity.min() > 0.1
    assert {c["friction"] for c in drawn.values()} == {0.5}


def test_a_truncation_past_the_bounds_is_narrowed_to_them_and_said():
    from contextrl.carl.context.context_space import NormalFloatContextFeature
    from contextrl.carl.context.sampler import ContextSampler

    wide = NormalFloatContextFeature("gravity", mu=9.8, sigma=40.0, lower=-100.0, upper=1000.0)
    with pytest.warns(UserWarning, match=r"reaches past the feature's bounds \[0.1, 100\]"):
        sampler = ContextSampler([wide], CARLCartPole.get_context_space(), seed=0)
    gravity = np.array([c["gravity"] for c in sampler.sample_contexts(500).values()])
    assert 0.1 <= gravity.min() and gravity.max() <= 100.0 and gravity.std() > 10.0
    point = NormalFloatContextFeature("gravity", mu=9.8, sigma=0.0, lower=1.0, upper=20.0)
    fixed = ContextSampler([point], CARLCartPole.get_context_space(), seed=0).sample_contexts(3)
    assert [c["gravity"] for c in fixed.values()] == [9.8] * 3
    one_sided = NormalFloatContextFeature("gravity", mu=9.8, sigma=1.0, lower=-5.0)  # no upper
    with pytest.warns(UserWarning, match=r"truncated to \[-5, 100\] .* drawing from \[0.1, 100\]"):
        ContextSampler([one_sided], CARLCartPole.get_context_space(), seed=0)
    apart = NormalFloatContextFeature("gravity", mu=500.0, sigma=1.0, lower=200.0, upper=900.0)
    with pytest.raises(crl.ContextError, match="does not meet the feature's bounds"):
        ContextSampler([apart], CARLCartPole.get_context_space(), seed=0)
    with pytest.raises(ValueError, match="list or dict of context features"):
        ContextSampler(0, CARLCartPole.get_context_space(), seed=0)


def test_carl_gymnasium_ids_make_the_face_classes():
    import contextrl.carl  # noqa: F401  (registers carl/<Name>-v0 as importing CARL does)

    env = gymnasium.make("carl/CARLPendulum-v0", contexts={0: {"l": 0.8}})
    obs, info = env.reset(seed=0)
    assert isinstance(env.unwrapped, ContextualGymEnv) and obs["context"]["l"][0] == np.float32(0.8)
    assert isinstance(env.env.env, CARLPendulum)
    assert "carl/CARLDmcWalkerEnv-v0" in gymnasium.registry


def test_carl_envs_lists_its_environment_classes_as_module_attributes():
    import contextrl.carl.envs as envs
    import contextrl.carl.envs.gymnasium as gymnasium_envs
    from contextrl.carl.envs.carl_env import CARLEnv

    assert {"CARLCartPole", "CARLPendulum", *envs.carl_names()} <= set(vars(envs))
    # as in CARL, every CARL name there is an environment to build (CARL's test_init_all_envs)
    named = [value for name, value in vars(envs).items() if "CARL" in name]
    assert named and all(issubclass(value, CARLEnv) and value.env_id for value in named)
    assert vars(envs)["CARLCartPole"] is CARLCartPole and "CARLCartPole" in dir(envs)
    assert set(envs.carl_names("classic_control")) <= set(vars(gymnasium_envs))


def test_carls_lunarlander_demo_runs_its_way_on_the_face():
    """CARL's demo_heuristic_lunarlander.py, our equivalent: gymnasium's heuristic reads
    ``env.unwrapped.continuous``, episodes are reset with a seed each and still go round the contexts,
    and ``render_mode = "human"`` set on the class gives frames, said in a warning (a host environment
    opens no window); a classic-control class opens one (SDL's dummy driver here).

    Measured (seeds 0–7, gravity −10 and −5): the heuristic's returns 193–320; it lands above 100."""
    from gymnasium.envs.box2d.lunar_lander import heuristic

    from contextrl.carl.envs import CARLLunarLander

    env = CARLLunarLander(contexts={0: {"GRAVITY_Y": -10.0}, 1: {"GRAVITY_Y": -5.0}})
    returns, ids = [], []
    for seed in range(3):
        obs, info = env.reset(seed=seed)
        ids.append(info["context_id"])
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(heuristic(env, obs["obs"]))
            total, done = total + reward, terminated or truncated
        returns.append(total)
    assert ids == [0, 1, 0] and min(returns) > 100
    # A pygame window breaks MuJoCo's EGL rendering later in the same process: in a process of its own.
    window = subprocess.run(
        [sys.executable, "-c", HUMAN_WINDOW],
        capture_output=True,
        text=True,
        env={**os.environ, "SDL_VIDEODRIVER": "dummy"},
    )
    assert window.returncode == 0, window.stderr
    assert window.stdout.splitlines() == ["rgb_array (400, 600, 3)", "human None"]
    assert 'render_mode "rgb_array" instead of "human"' in window.stderr


HUMAN_WINDOW = """
from contextrl.carl.envs import CARLCartPole, CARLLunarLander
for cls in (CARLLunarLander, CARLCartPole):
    cls.render_mode = "human"
    shown = cls()
    shown.reset(seed=0)
    frame = shown.render()  # a window's frame is drawn into it: None
    print(shown.unwrapped.render_mode, None if frame is None else tuple(frame.shape))
    shown.close()
"""


def test_a_selector_brings_its_own_contexts_and_context_id_switches_them():
    """CARL's manually_switch_contexts notebook, our equivalent on CartPole (its Finger lengths lie
    outside CARL's own bounds): the selector's contexts are the set, context_id picks the next one."""
    from contextrl.carl.context.selection import StaticSelector

    long_pole = {**CARLCartPole.get_default_context(), "length": 1.0}
    contexts = {0: CARLCartPole.get_default_context(), 1: long_pole}
    env = CARLCartPole(context_selector=StaticSelector(contexts))
    env.reset(seed=0)
    assert env.context["length"] == 0.5
    env.context_id = 1
    assert [env.reset()[1]["context"]["length"] for _ in range(2)] == [1.0, 1.0]


def test_carls_sb3_example_trains_dqn_on_a_carl_gymnasium_id():
    """CARL's carl_with_sb3.py, our equivalent (fewer steps): contexts from a sampler, the environment
    from ``gymnasium.make("carl/CARLLunarLander-v0", ...)``, flattened, trained and evaluated by SB3."""
    pytest.importorskip("stable_baselines3")
    from gymnasium.wrappers import FlattenObservation
    from stable_baselines3 import DQN
    from stable_baselines3.common.evaluation import evaluate_policy

    from contextrl.carl.context.context_space import NormalFloatContextFeature
    from contextrl.carl.context.sampler import ContextSampler
    from contextrl.carl.envs import CARLLunarLander

    gravity = NormalFloatContextFeature("GRAVITY_X", mu=9.8, sigma=1, upper=50, lower=0)
    with pytest.warns(UserWarning, match="reaches past the feature's bounds"):
        sampler = ContextSampler([gravity], CARLLunarLander.get_context_space(), seed=42)
    contexts = sampler.sample_contexts(n_contexts=5)
    env = FlattenObservation(
        gymnasium.make("carl/CARLLunarLander-v0", render_mode="rgb_array", contexts=contexts)
    )
    model = DQN("MlpPolicy", env, learning_starts=100, seed=0).learn(total_timesteps=300)
    mean_reward, _ = evaluate_policy(model, model.get_env(), n_eval_episodes=1)
    assert np.isfinite(mean_reward)
    assert env.get_wrapper_attr("contexts") == contexts
    assert all(0.0 <= c["GRAVITY_X"] <= 20.0 for c in contexts.values())


def test_brax_goal_contexts_in_carls_codes_choose_the_goal_variant():
    """CARL's brax_with_goals notebook, our equivalent without stepping (Brax compiles for minutes on
    a CPU; tests/envs/brax/test_brax.py steps the goal variant): CARL's direction codes in and out, the goal
    variant built when a context moves the target, the stock task otherwise."""
    pytest.importorskip("brax")
    from contextrl.carl.context.context_space import (
        CategoricalContextFeature,
        NormalFloatContextFeature,
    )
    from contextrl.carl.context.sampler import ContextSampler
    from contextrl.carl.envs.brax import CARLBraxAnt, CARLBraxHalfcheetah
    from contextrl.carl.envs.brax.brax_walker_goal_wrapper import directions
    from contextrl.carl.envs.brax.carl_brax_env import goal_sentence

    assert CARLBraxAnt.get_default_context()["target_direction"] == 2  # east, the stock forward
    assert CARLBraxHalfcheetah.get_context_features()["target_direction"].choices == [2, 4]
    distance = NormalFloatContextFeature("target_distance", mu=9.8, sigma=1, upper=50, lower=0)
    direction = CategoricalContextFeature("target_direction", choices=directions)
    with pytest.warns(UserWarning, match="drawing from \\[1, 50\\]"):
        sampler = ContextSampler([distance, direction], CARLBraxAnt.get_context_space(), seed=0)
    contexts = sampler.sample_contexts(40)
    assert {c["target_direction"] for c in contexts.values()} <= set(directions)
    assert len({c["target_direction"] for c in contexts.values()}) > 8
    contexts[0] = {**contexts[0], "target_direction": 112}  # CARL's north-north-east
    env = CARLBraxAnt(contexts=contexts, use_language_goals=True)
    assert env.unwrapped.contextrl_env.goal and "goal" in env.observation_space.spaces
    schedule = env.unwrapped.schedule  # the run's contexts hold contextrl's compass names
    first = schedule.values_dict(np.asarray(schedule.space.to_array(schedule.contexts[0])))
    assert first["target_direction"] == "NNE" and env.contexts == contexts  # shown in CARL's codes
    stock = CARLBraxAnt(contexts={0: {"gravity": 5.0}})
    assert not stock.unwrapped.contextrl_env.goal
    assert "target_distance" not in stock.observation_space["context"].spaces
    sentence = goal_sentence(
        {"target_distance": 20.0, "target_direction": 112, "target_radius": 5.0}
    )
    assert sentence.startswith("Reach the target 20 m to the north north east")
    with pytest.raises(crl.ContextError, match="not one of CARL's codes"):
        CARLBraxAnt(contexts={0: {"target_direction": 5}})
