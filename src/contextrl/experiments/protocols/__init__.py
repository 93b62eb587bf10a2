"""The paper's protocols (and the curriculum protocol), one module each: its spec (a frozen dataclass), its expansion into trials
and its report sections, named by a :class:`contextrl.experiments.protocol.Protocol` record.
Importing the package registers them all."""

from contextrl.experiments.protocols import (  # noqa: F401  (registers the protocols)
    curriculum,
    hpo,
    optimality_gap,
    sensitivity,
    tabular,
    train_test,
    visibility,
)
