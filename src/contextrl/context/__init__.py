"""The context model: feature declarations, spaces, distributions, sampling, selectors, observation."""

from contextrl.context.changes import Piecewise, RandomWalk, Redraw, StepFunction
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
    Coherence,
    ContextBase,
    ContextError,
    ContextSpace,
    Feature,
    context_type,
    feature,
)
from contextrl.context.observation import ContextObservation
from contextrl.context.schedule import RESAMPLED_ID, ContextSchedule, resolve_contexts
from contextrl.context.selectors import (
    DEFAULT_SELECTOR,
    Custom,
    FromSet,
    RandomSelector,
    Resample,
    RoundRobin,
    Static,
    make_selector,
)

__all__ = [
    "DEFAULT_SELECTOR",
    "RESAMPLED_ID",
    "Categorical",
    "Coherence",
    "Constant",
    "ContextBase",
    "ContextError",
    "ContextObservation",
    "ContextSchedule",
    "ContextSpace",
    "Custom",
    "Feature",
    "FromSet",
    "LogUniform",
    "Normal",
    "Piecewise",
    "RandomSelector",
    "RandomWalk",
    "Redraw",
    "RelativeUniform",
    "Resample",
    "RoundRobin",
    "Scaled",
    "Static",
    "StepFunction",
    "Uniform",
    "check_spec",
    "context_type",
    "feature",
    "make_selector",
    "resolve_contexts",
    "sample",
]
