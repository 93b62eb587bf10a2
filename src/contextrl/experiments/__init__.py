"""The paper's experiments as typed specs: protocols, run directories, executors, reports.

from contextrl import experiments
run, summary = experiments.run_experiment({"protocol": "optimality_gap", "env": "CartPole"})
experiments.report(run.path)

Each protocol is one module in :mod:`contextrl.experiments.protocols` (its spec class, expansion into
trials and report sections, named by a :class:`Protocol` record), the machinery they share beside it;
importing the package registers them all.
"""

from contextrl.experiments import protocols  # noqa: F401  (registers the protocols)
from contextrl.experiments.plan import Plan, Trial, expand
from contextrl.experiments.protocol import PROTOCOLS, Protocol, protocol_names, register_protocol
from contextrl.experiments.runner import carry_on, open_run, prepare, report, resume, run_experiment
from contextrl.experiments.runs import RunDir
from contextrl.experiments.spec import SPECS, SpecError, parse_spec, spec_to_dict

__all__ = [
    "PROTOCOLS",
    "SPECS",
    "Plan",
    "Protocol",
    "RunDir",
    "SpecError",
    "Trial",
    "carry_on",
    "expand",
    "open_run",
    "parse_spec",
    "prepare",
    "protocol_names",
    "register_protocol",
    "report",
    "resume",
    "run_experiment",
    "spec_to_dict",
]
