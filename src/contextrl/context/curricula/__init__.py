"""Curricula over contexts inside a compiled training loop: SPaCE, ADR and PLR on one mechanism.

A curriculum's state is data the loop carries; between rollouts the loop hands it per-context
:class:`Feedback` and draws the next rollout's contexts from ``curriculum.provider(state)``. Pass one
where an agent takes its training contexts::

    curriculum = PLR(crl.sample(env, {"pole_length": Uniform(0.1, 5.0)}, 64, key))
    train = ppo.make_train(config, env, curriculum)
"""

from contextrl.context.curricula.adr import ADR, ADRState, EdgeSampler
from contextrl.context.curricula.base import Curriculum, Feedback, WeightedSet
from contextrl.context.curricula.plr import PLR, PLRState
from contextrl.context.curricula.space import SPaCE, SPaCEState

CURRICULA = {"space": SPaCE, "adr": ADR, "plr": PLR}

__all__ = [
    "ADR",
    "CURRICULA",
    "PLR",
    "ADRState",
    "Curriculum",
    "EdgeSampler",
    "Feedback",
    "PLRState",
    "SPaCE",
    "SPaCEState",
    "WeightedSet",
]
