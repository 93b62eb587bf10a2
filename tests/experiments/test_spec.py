"""Specs are refused before anything runs; plans expand deterministically into the right contexts."""

import os
import re

import numpy as np
import pytest

from contextrl.experiments import (
    SpecError,
    expand,
    parse_spec,
    prepare,
    run_experiment,
    spec_to_dict,
)
from contextrl.experiments.protocols.train_test import REGIONS, region_of, train_test_contexts
from tests.helpers import ROOT

pytestmark = pytest.mark.quick

BAD_SPECS = [
    ({"protocol": "nope"}, "unknown protocol 'nope'"),
    ({"protocol": "visibility", "env": "CartPool"}, "unknown environment 'CartPool'"),
    ({"protocol": "visibility", "train": {"pole_lenght": {"uniform": [0.3, 0.6]}}}, "pole_lenght"),
    ({"protocol": "visibility", "train": {"length": {"uniform": [0.7, 0.3]}}}, "empty"),
    ({"protocol": "visibility", "train": {}}, "at least one feature"),
    ({"protocol": "visibility", "train": {"length": {"uniform": [0.3, 50.0]}}}, "bounds"),
    (
        {"protocol": "visibility", "train": {"length": {"gauss": [0.5, 0.1]}}},
        "unknown distribution",
    ),
    ({"protocol": "visibility", "agent": "dqn2"}, "unknown agent 'dqn2'"),
    ({"protocol": "visibility", "variants": ["hidden", "peek"]}, "unknown variant 'peek'"),
    ({"protocol": "visibility", "seeds": 0}, "seeds"),
    ({"protocol": "visibility", "seeds": 2.5}, "seeds"),
    ({"protocol": "visibility", "colour": "red"}, "unknown field"),
    ({"protocol": "sensitivity", "magnitudes": [1.0, float("nan")]}, "magnitudes"),
    ({"protocol": "sensitivity", "features": ["masscart", "wheels"]}, "wheels"),
    ({"protocol": "optimality_gap", "num_contexts": 0}, "num_contexts"),
    (
        {"protocol": "train_test", "test_box": {"length": [0.3, 1.5], "tau": [0.005, 0.05]}},
        "overlaps the train range",
    ),
    (
        {"protocol": "train_test", "test_box": {"length": [0.05, 1.5], "gravity": [1, 20]}},
        "same two features",
    ),
    ({"protocol": "train_test", "modes": ["A", "D"]}, "unknown mode 'D'"),
    ({"protocol": "tabular", "states": 30}, "too many"),
    ({"protocol": "visibility", "agent_options": {"learning_rat": 0.1}}, "learning_rat"),
    ({"protocol": "visibility", "agent_options": {"num_envs": -1}}, "num_envs"),
    ({"protocol": "visibility", "agent": "c51", "agent_options": {"num_atoms": 1}}, "atoms"),
    ({"protocol": "visibility", "agent": "dqn", "agent_options": {"clip_eps": 0.2}}, "clip_eps"),
]


@pytest.mark.parametrize(("data", "message"), BAD_SPECS)
def test_bad_spec_is_refused_before_anything_runs(data, message, tmp_path):
    with pytest.raises(SpecError, match=message):
        run_experiment(data, root=tmp_path / "runs", progress=False)
    assert not (tmp_path / "runs").exists()


def test_spec_round_trips_through_plain_data():
    spec = prepare({"protocol": "train_test", "agent": "random", "variants": ["hidden"]})
    assert parse_spec(spec_to_dict(spec)) == spec


def test_distribution_strings_and_aliases():
    spec = parse_spec({"protocol": "visibility", "train": {"pole_length": "uniform:0.3:0.6"}})
    plan = expand(spec)
    lengths = np.asarray(plan.sets["train"].contexts.length)
    assert lengths.min() >= 0.3 and lengths.max() <= 0.6 and np.unique(lengths).size > 1


def test_sensitivity_scales_each_feature_with_one_default_context():
    spec = parse_spec(
        {"protocol": "sensitivity", "features": ["length", "masspole"], "magnitudes": [0.5, 1, 2]}
    )
    plan = expand(spec)
    scaled = plan.sets["scaled"]
    # the default context once (A = 1 for every feature), then A = 0.5 and 2 per feature
    assert scaled.labels["feature"] == ["(default)", "length", "length", "masspole", "masspole"]
    assert scaled.labels["magnitude"] == [1.0, 0.5, 2.0, 0.5, 2.0]
    np.testing.assert_allclose(np.asarray(scaled.contexts.length), [0.5, 0.25, 1.0, 0.5, 0.5])
    np.testing.assert_allclose(np.asarray(scaled.contexts.masspole), [0.1, 0.1, 0.1, 0.05, 0.2])
    assert [t.train_set for t in plan.trials] == ["default"] * spec.seeds


def test_sensitivity_refuses_magnitudes_it_would_drop():
    # length 0.5 x 20 = 10 > bound 5: a named feature never silently loses a magnitude
    with pytest.raises(SpecError, match=r"A=20 gives length = 10, outside its bounds \[0.05, 5\]"):
        parse_spec({"protocol": "sensitivity", "features": ["length"], "magnitudes": [0.5, 20.0]})
    # with every feature, a magnitude is refused only when no feature can take it...
    with pytest.raises(SpecError, match=r"\[1000\] put every feature outside its bounds"):
        parse_spec({"protocol": "sensitivity", "magnitudes": [0.5, 1000]})
    # ...and the pairs left out are listed in the report
    spec = parse_spec({"protocol": "sensitivity", "magnitudes": [0.5, 10.0]})
    kept, skipped = spec.scaled_values()
    assert skipped == ["initial_state_lower at A=10", "initial_state_upper at A=10"]
    assert ("length", 10.0, 5.0) in kept


def test_optimality_gap_plan_pairs_each_specialist_with_its_context():
    spec = parse_spec({"protocol": "optimality_gap", "num_contexts": 5, "seeds": 2})
    plan = expand(spec)
    train = plan.sets["train"].contexts
    assert len(plan.trials) == 2 * (1 + 5)
    lengths = np.asarray(train.length)
    assert lengths.min() >= 0.25 and lengths.max() <= 0.75
    for i in range(5):
        assert float(plan.sets[f"train[{i}]"].contexts.length[0]) == lengths[i]
    # every specialist shares one chunk shape; the general agents another
    assert sorted(len(c) for c in plan.chunks) == [2, 10]
    assert expand(spec).sets["train"].contexts.length.tolist() == lengths.tolist()  # deterministic


def test_regions_of_kirk_protocol():
    box = [(0.0, 1.0), (0.0, 1.0)]
    assert region_of((0.5, 0.5), box, "A", 0.1) == REGIONS[0]
    assert region_of((0.5, 0.5), box, "B", 0.1) == REGIONS[1]  # inside box, off the L band
    assert region_of((0.05, 0.5), box, "B", 0.1) == REGIONS[0]  # on the band
    assert region_of((0.0, 0.7), box, "C", 0.1) == REGIONS[0]  # on an edge
    assert region_of((1.5, 0.5), box, "A", 0.1) == REGIONS[2]
    assert region_of((1.5, -0.5), box, "C", 0.1) == REGIONS[3]


def test_train_modes_lie_on_their_support_and_sampling_always_ends():
    import jax

    spec = parse_spec({"protocol": "train_test", "num_train_contexts": 20_000})
    (x0, x1), (y0, y1) = spec.boxes()[0].values()
    for mode in "ABC":
        contexts = train_test_contexts(spec, mode, jax.random.key(0))
        x, y = np.asarray(contexts.length), np.asarray(contexts.tau)
        assert len(x) == 20_000
        assert np.all((x >= x0 - 1e-6) & (x <= x1 + 1e-6) & (y >= y0 - 1e-6) & (y <= y1 + 1e-6))
        if mode == "C":
            assert np.all(np.isclose(x, x0) | np.isclose(y, y0))
        if mode == "B":
            band = (x <= x0 + 0.1 * (x1 - x0) + 1e-6) | (y <= y0 + 0.1 * (y1 - y0) + 1e-6)
            assert np.all(band)


def test_example_specs_are_valid():

    import yaml

    files = sorted(ROOT.glob("examples/*.yaml"))
    assert {f.stem.split("_")[0] for f in files} >= {
        "sensitivity",
        "optimality",
        "visibility",
        "train",
    }
    for file in files:
        spec = prepare(yaml.safe_load(file.read_text()))
        assert spec.protocol in file.stem.replace("-", "_") or spec.protocol == "tabular"


def test_agent_without_a_host_loop_is_refused_on_a_host_environment():
    import contextrl as crl
    from contextrl.agents import Agent, ppo, register_agent

    host = [i for i in crl.registered() if crl.spec(i).host]
    if not host:
        pytest.skip("no host environment registered (dm_control not installed)")
    register_agent(
        Agent("jax_only_ppo", ppo.PPOConfig, ppo.make_train, ppo.make_policy), replace=True
    )
    with pytest.raises(SpecError, match="jax_only_ppo agent has no host training loop.*'ppo'"):
        prepare({"protocol": "visibility", "env": host[0], "agent": "jax_only_ppo"})


def test_xla_workaround_adds_its_flag_once_and_respects_the_user(monkeypatch):
    from contextrl.xla_flags import xla_cpu_workaround

    monkeypatch.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=2")
    xla_cpu_workaround()
    xla_cpu_workaround()
    flags = os.environ["XLA_FLAGS"].split()
    assert flags == [
        "--xla_force_host_platform_device_count=2",
        "--xla_cpu_enable_concurrency_optimized_scheduler=false",
    ]
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_enable_concurrency_optimized_scheduler=true")
    xla_cpu_workaround()
    assert os.environ["XLA_FLAGS"].endswith("scheduler=true")


def test_an_environment_whose_extra_is_missing_names_the_extra(monkeypatch):
    """A shipped environment whose simulator is not installed (not registered) is named with the
    extra that brings it, in the spec's refusal and in ``crl.make``'s."""
    from contextrl.core import registry

    monkeypatch.delitem(registry._REGISTRY, "DmcWalker")
    extra = 'the dmc family, whose simulator is not installed: pip install "contextrl[dmc]"'
    with pytest.raises(SpecError, match=re.escape(extra)):
        parse_spec({"protocol": "visibility", "env": "DmcWalker", "agent": "random"})
    with pytest.raises(KeyError, match=re.escape(extra)):
        registry.spec("DmcWalker")
