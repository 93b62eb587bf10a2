"""The RNA design family on ViennaRNA (extra ``rna``: ``viennarna``, imported as ``RNA``)."""

from contextrl.envs.rna.design import (
    ACTION_PAIRS,
    CHANNELS,
    IMPROVEMENTS,
    RnaDesign,
    RnaDesignContext,
)
from contextrl.envs.rna.targets import (
    DATASETS,
    SyntheticTargets,
    Target,
    TargetError,
    TargetSets,
    fold,
    pair_table,
)

__all__ = [
    "ACTION_PAIRS",
    "CHANNELS",
    "DATASETS",
    "IMPROVEMENTS",
    "RnaDesign",
    "RnaDesignContext",
    "SyntheticTargets",
    "Target",
    "TargetError",
    "TargetSets",
    "fold",
    "pair_table",
]
