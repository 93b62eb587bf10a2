"""The context model: feature declarations, spaces, distributions, sampling, selectors, observation."""

from contextrl.context.distributions import (
    Categorical,
    Constant,
    LogUniform,
    Normal,
    RelativeUniform,
    Scaled,
    Uniform,
    check_spec,
    sample,
)
from contextrl.context.features import (
    ContextBase,
    ContextError,
    ContextSpace,
    Feature,
    context_type,
    feature,
)
from contextrl.context.observation import ContextObservation
from contextrl.context.selectors import (
    Custom,
    FromSet,
    RandomSelector,
    Resample,
    RoundRobin,
    Static,
    make_selector,
)

__all__ = [
    "Categorical",
    "Constant",
    "ContextBase",
    "ContextError",
    "ContextObservation",
    "ContextSpace",
    "Custom",
    "Feature",
    "FromSet",
    "LogUniform",
    "Normal",
    "RandomSelector",
    "RelativeUniform",
    "Resample",
    "RoundRobin",
    "Scaled",
    "Static",
    "Uniform",
    "check_spec",
    "context_type",
    "feature",
    "make_selector",
    "sample",
]
