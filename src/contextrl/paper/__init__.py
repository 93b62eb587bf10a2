"""The paper's figures as runnable specs, checked claims and a results page (``contextrl paper``).

Each figure's spec ships in ``contextrl/paper/specs/<figure>.yaml`` (a figure of two runs, such as
PB2 with the context hidden and visible, has one file per part), its header stating the paper's
section, the claim, its decision rule and where its settings differ from the paper's. A checkout
also reaches them as ``examples/paper/`` (a link), so ``contextrl run --config
examples/paper/<figure>.yaml`` runs one part as an ordinary experiment.

- :mod:`~contextrl.paper.checks`: the decision rules and the verdicts they give;
- :mod:`~contextrl.paper.catalogue`: the figures, their checks and budgets at each scale;
- :mod:`~contextrl.paper.runs`: running a figure and reading its runs back;
- :mod:`~contextrl.paper.page`: ``docs/paper.md``, regenerated from the run folders alone (the
  project keeps its own runs' records in ``results/paper``, checkpoints and figures left out).
"""

from contextrl.paper.catalogue import FIGURES, SCALES, PaperFigure, spec_data
from contextrl.paper.checks import Verdict
from contextrl.paper.page import figure_rows, results_page
from contextrl.paper.runs import PAPER_RUNS, estimate, finished_runs, run_figure

__all__ = [
    "FIGURES",
    "PAPER_RUNS",
    "SCALES",
    "PaperFigure",
    "Verdict",
    "estimate",
    "figure_rows",
    "finished_runs",
    "results_page",
    "run_figure",
    "spec_data",
]
