"""The paper's experiments as typed specs: protocols, run directories, executors, reports.

from contextrl import experiments
run, summary = experiments.run_experiment({"protocol": "optimality_gap", "env": "CartPole"})
experiments.report(run.path)
"""

from contextrl.experiments.protocols import Plan, Trial, expand
from contextrl.experiments.runner import prepare, report, resume, run_experiment
from contextrl.experiments.runs import RunDir
from contextrl.experiments.spec import PROTOCOLS, SpecError, parse_spec, spec_to_dict

__all__ = [
    "PROTOCOLS",
    "Plan",
    "RunDir",
    "SpecError",
    "Trial",
    "expand",
    "parse_spec",
    "prepare",
    "report",
    "resume",
    "run_experiment",
    "spec_to_dict",
]
