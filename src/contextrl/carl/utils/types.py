"""CARL's type aliases: a context is a dict of feature values, a context set a mapping id → context."""

from typing import Any, TypeVar

import numpy as np

Context = dict[str, Any]
Contexts = dict[Any, Context]
Vector = list[Any] | np.ndarray
ObsType = TypeVar("ObsType")
