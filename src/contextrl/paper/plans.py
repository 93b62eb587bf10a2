"""The paper's specs expanded and parsed once each: the page reads every figure's specs several times
(budgets, estimates, checks), and expanding a spec draws its contexts."""

from __future__ import annotations

import functools

import yaml

from contextrl.experiments.plan import expand
from contextrl.experiments.spec import load_yaml, parse_spec, spec_to_dict


def training_steps(spec) -> int:
    """Environment steps the spec's agents train in all."""
    return spec.training_steps(planned(spec).trials)


def planned(spec):
    """``expand(spec)``, once per spec: expanding draws the contexts, and the page reads every
    figure's specs several times (budgets, estimates, checks)."""
    return _plan_of(yaml.safe_dump(spec_to_dict(spec), sort_keys=True))


@functools.cache
def _plan_of(text: str):
    return expand(parse_spec(yaml.safe_load(text)))


@functools.cache
def parsed_spec(text: str):
    """A run's spec.yaml parsed once: every estimate on the page reads every run's spec."""
    return parse_spec(load_yaml(text))
