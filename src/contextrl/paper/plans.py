"""The paper's specs outlined, expanded and parsed once each: the page reads every figure's specs
several times (budgets, estimates, checks). Counting steps and chunks reads a spec's outline, which
draws no contexts; only what reads the contexts themselves expands it."""

from __future__ import annotations

import functools
import json
from collections.abc import Callable

from contextrl.experiments.plan import Outline, Plan, expand, outline
from contextrl.experiments.spec import load_yaml, parse_spec, spec_to_dict

_OUTLINES: dict[str, Outline] = {}
_PLANS: dict[str, Plan] = {}


def training_steps(spec) -> int:
    """Environment steps the spec's agents train in all."""
    return spec.training_steps(outlined(spec).trials)


def outlined(spec) -> Outline:
    """``outline(spec)``, once per spec: its sets' sizes, trials and chunks, no context drawn."""
    return _once(_OUTLINES, outline, spec)


def planned(spec) -> Plan:
    """``expand(spec)``, once per spec: expanding draws the contexts, and the page reads every
    figure's specs several times (budgets, estimates, checks)."""
    return _once(_PLANS, expand, spec)


def _once(made: dict, make: Callable, spec):
    """``make(spec)``, kept in ``made`` under the spec's data: equal specs share it."""
    key = json.dumps(spec_to_dict(spec), sort_keys=True, default=repr)
    if key not in made:
        made[key] = make(spec)
    return made[key]


@functools.cache
def parsed_spec(text: str):
    """A run's spec.yaml parsed once: every estimate on the page reads every run's spec."""
    return parse_spec(load_yaml(text))
