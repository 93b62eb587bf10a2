"""``contextrl paper list`` and ``page`` count steps and chunks from each spec's outline, which draws
no contexts: at every scale, every figure's outline is its plan's sizes, trials and chunks."""

from __future__ import annotations

import pytest

from contextrl.experiments.plan import Outline, expand, outline
from contextrl.experiments.spec import parse_spec
from contextrl.paper.catalogue import FIGURES, SCALES, spec_data
from contextrl.paper.runs import _new_part


@pytest.mark.parametrize("scale", SCALES)
def test_every_figures_outline_is_its_plan_at_every_scale(scale):
    for figure in FIGURES.values():
        for part in figure.files():
            listed = parse_spec(spec_data(figure, part, scale))  # what the page counts
            run = parse_spec(_new_part(figure, part, scale, None))  # what `paper run` writes
            for spec in [listed] if run == listed else [listed, run]:
                plan = expand(spec)
                drawn = Outline(spec, plan.sizes, plan.trials, plan.chunks)
                assert outline(spec) == drawn, f"{figure.name}/{part} at the {scale} scale"
