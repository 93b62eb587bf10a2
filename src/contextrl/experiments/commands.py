"""The ``contextrl run`` and ``contextrl report`` subcommands (added to the CLI's subparsers).

A spec is built in layers: a preset (``quickstart``) or just the protocol name, then ``--config
spec.yaml``, then the command-line options, so a YAML file can be rerun with one field changed.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import sys
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import contextrl as crl
from contextrl.agents import get_agent, registered_agents
from contextrl.experiments.compare import compare_runs
from contextrl.experiments.protocol import PROTOCOLS
from contextrl.experiments.reevaluate import evaluate_run
from contextrl.experiments.reports import learning_verdict
from contextrl.experiments.runner import prepare, preview, report, resumable, run_experiment
from contextrl.experiments.runs import RunDir, write_text
from contextrl.experiments.spec import (
    SpecError,
    agent_options_error,
    load_yaml,
    parse_assignments,
    parse_distribution,
)

# The main job: CartPole with the pole length varied, hidden vs concat agents, a train/test split with
# held-out and longer/shorter poles; a few minutes on 2 CPU cores.
QUICKSTART: dict[str, Any] = {
    "protocol": "visibility",
    "name": "quickstart",
    "env": "CartPole",
    "agent": "ppo",
    "agent_options": {"total_timesteps": 100_000, "num_envs": 8},
    "variants": ["hidden", "concat_varying"],
    "seeds": 5,
    "train": {"length": {"uniform": [0.25, 0.75]}},
    "test": {"length": {"uniform": [0.1, 1.5]}},
    "num_train_contexts": 32,
    "num_test_contexts": 64,
    "eval_episodes": 5,
    "bootstrap_reps": 2000,
}
PRESETS = {"quickstart": QUICKSTART}


def count(text: str) -> int:
    """An argparse type for counts that also reads ``1e5`` (a whole number written with an exponent)."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if not value.is_integer():
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}")
    return int(value)


def positive(text: str) -> int:
    """A :func:`count` of at least 1 (a number of chunks: 0 or fewer would run nothing, or all but
    the last)."""
    value = count(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number of at least 1, got {text!r}")
    return value


def _load_yaml_file(path: str, option: str) -> Any:
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as error:
        raise SpecError(f"{option} {path}: {error.strerror or error}") from None
    return load_yaml(text, f"{option} {path}")


def _load_config(path: str) -> dict[str, Any]:
    loaded = _load_yaml_file(path, "--config")
    if not isinstance(loaded, dict):
        raise SpecError(f"--config {path}: expected a YAML mapping of spec fields")
    return loaded


def spec_from_args(args: argparse.Namespace, notices: list[str] | None = None) -> dict[str, Any]:
    """The spec mapping of ``contextrl run`` (validated later, before anything runs); what options
    did on top of the config (``--vary`` keeping some of its features) is appended to ``notices``."""
    loaded = _load_config(args.config) if args.config else {}
    protocol = args.protocol or loaded.get("protocol")
    if protocol is None:
        raise SpecError(
            "give a protocol (or quickstart), a --config that names one, or --resume DIR"
        )
    if protocol in PRESETS:
        data = {k: v.copy() if isinstance(v, dict) else v for k, v in PRESETS[protocol].items()}
    elif protocol in PROTOCOLS:
        data = {"protocol": protocol}
    else:
        raise SpecError(f"unknown protocol {protocol!r}; choose one of {[*PRESETS, *PROTOCOLS]}")
    if loaded:
        if loaded.get("protocol", data["protocol"]) != data["protocol"]:
            raise SpecError(
                f"--config {args.config} is a {loaded['protocol']} spec, not {data['protocol']}"
            )
        data.update(loaded)
    simple = {
        "env": args.env,
        "agent": args.agent,
        "seeds": args.seeds,
        "seed": args.seed,
        "name": args.name,
        "eval_episodes": args.episodes,
        "max_steps": args.max_steps,
    }
    written_for = data.get("agent", "ppo")  # the agent the preset's or config's options are for
    data.update({k: v for k, v in simple.items() if v is not None})
    _leave_preset_contexts(protocol, data, loaded, notices)
    if args.variants is not None:
        data["variants"] = args.variants.split(",")
    options = data.get("agent_options") or {}
    if not isinstance(options, Mapping):
        raise SpecError(agent_options_error(options))
    options = dict(options)
    if args.agent is not None and args.agent != written_for and options:
        if notices is not None:
            notices.append(
                f"note: the spec's agent_options were written for {written_for}, so --agent "
                f"{args.agent} trains without them: {options}"
            )
        options = {}
    if args.timesteps is not None and not get_agent(data.get("agent", "ppo")).trained:
        raise SpecError(
            f"--timesteps {args.timesteps}: the {data.get('agent')} agent does not train; "
            "leave --timesteps out"
        )
    if args.agent_config:
        loaded = _load_yaml_file(args.agent_config, "--agent-config")
        if not isinstance(loaded, dict):
            raise SpecError(
                f"--agent-config {args.agent_config}: expected a YAML mapping of agent options "
                "(as written by contextrl run hpo)"
            )
        options.update(loaded)
    if args.timesteps is not None:
        options["total_timesteps"] = args.timesteps
    options.update(parse_assignments(args.agent_option, "--agent-option"))
    data.pop("agent_options", None)
    if options:
        data["agent_options"] = options
    if args.vary:
        notice = PROTOCOLS[data["protocol"]].vary_spec(data, args.vary)
        if notice and notices is not None:
            notices.append(notice)
    if args.test:
        data["test"] = parse_assignments(args.test, "--test", "FEATURE=DIST", parse_distribution)
    sets = parse_assignments(args.set, "--set")
    for field, flag in FLAGGED_FIELDS.items():
        value = getattr(args, flag.removeprefix("--").replace("-", "_"))
        if field in sets and value is not None:
            raise SpecError(
                f"--set {field}={sets[field]} and {flag} {value} both set {field}; give one"
            )
    data.update(sets)
    return data


def _budget_typed(args: argparse.Namespace) -> bool:
    """Whether the command line gives the training budget (--timesteps, --agent-option): where it
    is rounded down to whole rollouts or logging periods, the run says so."""
    return args.timesteps is not None or any("total_timesteps" in o for o in args.agent_option)


# Spec fields that have a flag of their own: --set FIELD=... beside the flag is refused.
FLAGGED_FIELDS = {
    "env": "--env", "agent": "--agent", "seeds": "--seeds", "seed": "--seed", "name": "--name",
    "eval_episodes": "--episodes", "max_steps": "--max-steps", "variants": "--variants",
}  # fmt: skip


def _leave_preset_contexts(
    protocol: str, data: dict[str, Any], loaded: dict[str, Any], notices: list[str] | None
) -> None:
    """A preset's contexts vary its own environment's features: on another ``--env`` they are
    dropped, so that environment's protocol defaults apply (or ``--vary`` is asked for), said once."""
    preset = PRESETS.get(protocol)
    if preset is None or _env_id(data["env"]) == preset["env"]:
        return
    dropped = [name for name in ("train", "test") if name not in loaded and name in data]
    for name in dropped:
        del data[name]
    if dropped and notices is not None:
        notices.append(
            f"note: {protocol}'s contexts vary {preset['env']}'s {', '.join(preset['train'])}, so "
            f"on {data['env']} they are left out: --vary and --test set them, else "
            f"{data['env']}'s defaults for the {data['protocol']} protocol apply"
        )


def _env_id(name: Any) -> Any:
    """The registry id of an environment name or alias (the name itself when unknown: the spec's
    validation names it)."""
    try:
        return crl.spec(name).id
    except (KeyError, TypeError):
        return name


# Options that shape a spec: refused with --resume, which continues the run its spec.yaml describes.
SPEC_OPTIONS = (
    "protocol", "config", "env", "agent", "variants", "seeds", "seed", "timesteps", "episodes",
    "max_steps", "vary", "test", "agent_option", "agent_config", "set", "name", "out",
)  # fmt: skip


def _refuse_spec_options(args: argparse.Namespace) -> None:
    given = [name for name in SPEC_OPTIONS if getattr(args, name) not in (None, [], False)]
    if given:
        flags = ", ".join("--" + name.replace("_", "-") for name in given).replace(
            "--protocol", "PROTOCOL"
        )
        raise SpecError(
            f"--resume {args.resume} continues the run as its spec.yaml says; {flags} cannot "
            "apply (only --executor, --address, --max-chunks, --quiet, --verbose, --log and "
            "--dry-run do). Start a new run to change the spec"
        )


class _Interrupt:
    """Ctrl-C stops ``contextrl run`` within a second, whatever it is doing (compiling included).

    Python runs signal handlers in the main thread between bytecodes, so during a long compile a
    handler waits. But the C-level handler writes the signal number to the wakeup fd at once, from
    any thread: a watcher thread reading it prints how to resume and exits the process there and then.
    A half-written file is a temporary name that a resumed run ignores, so nothing needs cleaning up;
    child processes (a local Ray) get the terminal's Ctrl-C themselves.
    """

    def __init__(self) -> None:
        self.run_path: Path | None = None
        self.on_exit: list = []
        self._lock = threading.Lock()
        self._reader, self._writer = socket.socketpair()
        self._writer.setblocking(False)
        self.previous_fd = signal.set_wakeup_fd(self._writer.fileno())
        self.previous = signal.signal(signal.SIGINT, lambda signum, frame: self.stop())
        threading.Thread(target=self._wait, name="contextrl-interrupt", daemon=True).start()

    def watch(self, run: RunDir, flush) -> None:
        """From now on an interrupt names ``run`` to resume and first calls ``flush`` (a log's)."""
        self.run_path = run.path
        if flush is not None:
            self.on_exit.append(flush)

    def _wait(self) -> None:
        while data := self._reader.recv(64):
            if signal.SIGINT in data:
                self.stop()

    def stop(self) -> None:
        with self._lock:
            hint = (
                f"; resume with: contextrl run --resume {self.run_path}"
                if self.run_path is not None
                else ""
            )
            for callback in self.on_exit:
                callback()
            print(f"\ncontextrl run: interrupted{hint}", file=sys.stderr, flush=True)
            os._exit(130)

    def close(self) -> None:
        signal.set_wakeup_fd(self.previous_fd)
        signal.signal(signal.SIGINT, self.previous)
        self._writer.close()  # the watcher reads end-of-file and returns
        self._reader.shutdown(socket.SHUT_RDWR)


def _refuse_conflicts(args: argparse.Namespace) -> None:
    """Flags that cannot both apply, refused rather than one of them ignored."""
    if args.estimate and not args.dry_run:
        raise SpecError("--estimate goes with --dry-run (a run measures its own time)")
    if args.quiet and args.verbose:
        raise SpecError(
            "--quiet and --verbose: give one (quiet: no progress lines; verbose: Ray's)"
        )
    if args.resume:
        resumable(args.resume)  # a folder without a run is named before any other option
    if args.out and args.root != "runs":
        raise SpecError(
            f"--out {args.out} names the run directory, so --root {args.root} would be ignored; "
            "give one of them"
        )


def run_command(args: argparse.Namespace) -> int:
    _refuse_conflicts(args)
    if args.resume:
        _refuse_spec_options(args)
        target = {"resume": args.resume}
    else:
        notices: list[str] = []
        spec = prepare(spec_from_args(args, notices))
        if spec.trains_agents and _budget_typed(args):
            notices.append(spec.budget_note())
        for notice in filter(None, notices):
            print(notice, file=sys.stderr)
        target = {"spec": spec, "out": args.out, "root": args.root}
    where = {"executor": args.executor, "address": args.address}
    interrupt = _Interrupt()
    try:
        if args.dry_run:  # checked as the run is up to here; then nothing is created
            print(preview(**target, **where, estimate=args.estimate))
            return 0
        run, summary = run_experiment(
            **target,
            **where,
            max_chunks=args.max_chunks,
            progress=not args.quiet,
            verbose=args.verbose,
            log=args.log,
            on_start=interrupt.watch,
        )
    except (FileNotFoundError, FileExistsError) as error:
        raise SpecError(str(error)) from None
    finally:
        interrupt.close()
    print(f"report: {run.path / 'report.html'}")
    for line in learning_verdict(run):
        print(line)
    if summary.failed:
        print(
            f"{len(summary.failed)} chunk(s) failed; see the report, retry with --resume {run.path}"
        )
    if summary.remaining:
        print(
            f"{len(summary.remaining)} chunk(s) left; continue with: contextrl run --resume {run.path}"
        )
    return 1 if summary.failed else 0


def add_run(subparsers) -> None:
    parser = subparsers.add_parser(
        "run",
        help="run an experiment protocol and write a run directory with a report",
        description="Protocols: " + ", ".join([*PRESETS, *PROTOCOLS]) + ". Options override "
        "--config, which overrides the protocol's defaults.",
    )
    parser.add_argument("protocol", nargs="?", help=f"one of {[*PRESETS, *PROTOCOLS]}")
    parser.add_argument("--config", help="a YAML spec (see examples/*.yaml)")
    parser.add_argument("--env", help="environment id (contextrl list)")
    parser.add_argument("--agent", help=f"a registered agent: {registered_agents()}")
    parser.add_argument(
        "--variants", help="comma-separated: hidden,concat_all,concat_varying,gated"
    )
    parser.add_argument("--seeds", type=count, help="independent runs per variant")
    parser.add_argument("--seed", type=count, help="base seed of contexts, training and bootstrap")
    parser.add_argument("--timesteps", type=count, help="training steps per agent")
    parser.add_argument("--episodes", type=count, help="evaluation episodes per context")
    parser.add_argument("--max-steps", type=count, help="episode time limit")
    parser.add_argument(
        "--vary",
        action="append",
        default=[],
        metavar="FEATURE=DIST",
        help="training distribution, e.g. length=uniform:0.25:0.75 (train_test: length=[0.25,0.75]; "
        "sensitivity: feature names)",
    )
    parser.add_argument(
        "--test", action="append", default=[], metavar="FEATURE=DIST", help="test distribution"
    )
    parser.add_argument(
        "--agent-option", action="append", default=[], metavar="KEY=VALUE", help="agent config"
    )
    parser.add_argument(
        "--agent-config",
        metavar="YAML",
        help="agent options from a file, e.g. the best.yaml of an hpo run (--agent-option wins)",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="any spec field (YAML value)",
    )
    parser.add_argument("--name", help="run name (default: the protocol)")
    parser.add_argument("--out", help="run directory (default: ROOT/<name>-<time>)")
    parser.add_argument("--root", default="runs", help="where new run directories go")
    parser.add_argument("--resume", metavar="DIR", help="finish an interrupted run")
    parser.add_argument(
        "--executor",
        default="local",
        help="local (this process), processes (one worker per CPU core) or ray",
    )
    parser.add_argument(
        "--address", help="Ray cluster address for --executor ray and hpo (default: a local Ray)"
    )
    parser.add_argument(
        "--max-chunks", type=positive, help="stop after this many chunks (resume later)"
    )
    parser.add_argument(
        "--quiet",
        action="store_true",
        help="no progress lines, and no bars for the chunks in training",
    )
    parser.add_argument(
        "--verbose",
        action="store_true",
        help="show Ray's and Tune's own output (start-up lines, Tune's status tables) instead of "
        "writing it to ray/ray.log in the run directory",
    )
    parser.add_argument(
        "--dry-run",
        action="store_true",
        help="check the options as the run does, then print trials, chunks, environment steps and "
        "where the results would go; create, compile and train nothing",
    )
    parser.add_argument(
        "--estimate",
        action="store_true",
        help="with --dry-run: also estimate the time, from earlier runs of this spec under --root "
        "(free), else from one short compiled and timed call",
    )
    parser.add_argument(
        "--log",
        choices=["tensorboard"],
        help="also stream training curves and test returns to TensorBoard (RUN/tensorboard)",
    )
    parser.set_defaults(handler=run_command)


def report_command(args: argparse.Namespace) -> int:
    verdict: list[str] = []  # one run's learned-or-warn lines, as contextrl run ends with
    out = None if args.out is None else Path(args.out)
    if out is not None and out.suffix.lower() not in (".html", ".htm"):
        raise SpecError(f"--out {out}: the report is one HTML file; name it *.html")
    try:
        if len(args.run_dir) > 1:
            path = compare_runs(args.run_dir, out or Path("comparison.html"), force=args.force)
        else:
            path = report(args.run_dir[0])
            verdict = learning_verdict(RunDir(args.run_dir[0]))
            if out is not None:  # self-contained (figures inline): a copy reads the same anywhere
                path = write_text(out, Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError as error:
        raise SpecError(str(error)) from None
    print(f"report: {path}")
    for line in verdict:
        print(line)
    return 0


def add_report(subparsers) -> None:
    parser = subparsers.add_parser(
        "report",
        help="rebuild the HTML report of a run, or overlay several runs of one protocol",
    )
    parser.add_argument("run_dir", nargs="+", help="run directories written by contextrl run")
    parser.add_argument(
        "--out",
        help="the report's file (*.html): one run's is also kept as RUN/report.html; several "
        "runs' comparison goes to comparison.html by default",
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="with several runs: overlay runs of different protocols, environments or varied "
        "features (labelled) instead of refusing",
    )
    parser.set_defaults(handler=report_command)


def eval_command(args: argparse.Namespace) -> int:
    if not args.test:
        raise SpecError("eval: give the new contexts with --test FEATURE=DIST (repeatable)")
    test = parse_assignments(args.test, "--test", "FEATURE=DIST", parse_distribution)
    try:
        file, frame = evaluate_run(
            args.run_dir,
            test,
            num_contexts=args.contexts,
            episodes=args.episodes,
            name=args.name,
        )
    except FileNotFoundError as error:
        raise SpecError(str(error)) from None
    print(
        f"evaluated {frame['trial'].nunique()} agents on {frame['context_index'].nunique()} "
        f"contexts: {file}"
    )
    print(f"report: {Path(args.run_dir) / 'report.html'}")
    return 0


def add_eval(subparsers) -> None:
    parser = subparsers.add_parser(
        "eval", help="evaluate a run's saved agents on new contexts (no retraining)"
    )
    parser.add_argument("run_dir", help="a run directory written by contextrl run")
    parser.add_argument(
        "--test",
        action="append",
        default=[],
        metavar="FEATURE=DIST",
        help="new contexts, e.g. length=uniform:0.1:2.0 (repeatable; other features default)",
    )
    parser.add_argument("--contexts", type=count, default=64, help="contexts to draw (64)")
    parser.add_argument("--episodes", type=count, help="episodes per context (the run's)")
    parser.add_argument("--name", help="name of this evaluation (eval-1, eval-2, …)")
    parser.set_defaults(handler=eval_command)
