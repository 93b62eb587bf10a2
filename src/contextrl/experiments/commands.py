"""The ``contextrl run`` and ``contextrl report`` subcommands (added to the CLI's subparsers).

A spec is built in layers: a preset (``quickstart``) or just the protocol name, then ``--config
spec.yaml``, then the command-line options, so a YAML file can be rerun with one field changed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import yaml

from contextrl.agents import registered_agents
from contextrl.experiments.runner import report, resume, run_experiment
from contextrl.experiments.spec import SPECS, SpecError, parse_distribution

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


def _assignments(items: list[str], option: str) -> dict[str, Any]:
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise SpecError(f"{option}: expected NAME=VALUE, got {item!r}")
        out[name] = yaml.safe_load(value)
    return out


def spec_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The spec mapping of ``contextrl run`` (validated later, before anything runs)."""
    if args.protocol in PRESETS:
        data = {
            k: v.copy() if isinstance(v, dict) else v for k, v in PRESETS[args.protocol].items()
        }
    elif args.protocol in SPECS:
        data = {"protocol": args.protocol}
    else:
        raise SpecError(f"unknown protocol {args.protocol!r}; choose one of {[*PRESETS, *SPECS]}")
    if args.config:
        loaded = yaml.safe_load(Path(args.config).read_text(encoding="utf-8"))
        if not isinstance(loaded, dict):
            raise SpecError(f"--config {args.config}: expected a YAML mapping of spec fields")
        if loaded.get("protocol", data["protocol"]) != data["protocol"] and args.protocol in SPECS:
            raise SpecError(
                f"--config {args.config} is a {loaded['protocol']} spec, not {args.protocol}"
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
    data.update({k: v for k, v in simple.items() if v is not None})
    if args.variants:
        data["variants"] = args.variants.split(",")
    options = dict(data.get("agent_options") or {})
    if args.agent_config:
        loaded = yaml.safe_load(Path(args.agent_config).read_text(encoding="utf-8"))
        if not isinstance(loaded, dict):
            raise SpecError(
                f"--agent-config {args.agent_config}: expected a YAML mapping of agent options "
                "(as written by contextrl run hpo)"
            )
        options.update(loaded)
    if args.timesteps is not None:
        options["total_timesteps"] = args.timesteps
    options.update(_assignments(args.agent_option, "--agent-option"))
    if options:
        data["agent_options"] = options
    if args.vary:
        SPECS[data["protocol"]].vary(data, args.vary)
    if args.test:
        data["test"] = {
            name: parse_distribution(name, value)
            for name, value in (v.partition("=")[::2] for v in args.test)
        }
    data.update(_assignments(args.set, "--set"))
    return data


def run_command(args: argparse.Namespace) -> int:
    progress = not args.quiet
    try:
        if args.resume:
            run, summary = resume(
                args.resume,
                executor=args.executor,
                address=args.address,
                max_chunks=args.max_chunks,
                progress=progress,
            )
        else:
            if not args.protocol:
                raise SpecError("give a protocol (or quickstart), or --resume DIR")
            run, summary = run_experiment(
                spec_from_args(args),
                out=args.out,
                root=args.root,
                executor=args.executor,
                address=args.address,
                max_chunks=args.max_chunks,
                progress=progress,
            )
    except (FileExistsError, FileNotFoundError) as error:
        raise SpecError(str(error)) from None
    print(f"report: {run.path / 'report.html'}")
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
        description="Protocols: " + ", ".join([*PRESETS, *SPECS]) + ". Options override "
        "--config, which overrides the protocol's defaults.",
    )
    parser.add_argument("protocol", nargs="?", help=f"one of {[*PRESETS, *SPECS]}")
    parser.add_argument("--config", help="a YAML spec (see examples/*.yaml)")
    parser.add_argument("--env", help="environment id (contextrl list)")
    parser.add_argument("--agent", help=f"a registered agent: {registered_agents()}")
    parser.add_argument(
        "--variants", help="comma-separated: hidden,concat_all,concat_varying,gated"
    )
    parser.add_argument("--seeds", type=int, help="independent runs per variant")
    parser.add_argument("--seed", type=int, help="base seed of contexts, training and bootstrap")
    parser.add_argument("--timesteps", type=int, help="training steps per agent")
    parser.add_argument("--episodes", type=int, help="evaluation episodes per context")
    parser.add_argument("--max-steps", type=int, help="episode time limit")
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
    parser.add_argument("--executor", default="local", help="local or ray")
    parser.add_argument(
        "--address", help="Ray cluster address for --executor ray and hpo (default: a local Ray)"
    )
    parser.add_argument("--max-chunks", type=int, help="stop after this many chunks (resume later)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    parser.set_defaults(handler=run_command)


def report_command(args: argparse.Namespace) -> int:
    try:
        path = report(args.run_dir)
    except FileNotFoundError as error:
        raise SpecError(str(error)) from None
    print(f"report: {path}")
    return 0


def add_report(subparsers) -> None:
    parser = subparsers.add_parser("report", help="rebuild the HTML report of a run directory")
    parser.add_argument("run_dir", help="a run directory written by contextrl run")
    parser.set_defaults(handler=report_command)


def main(argv: list[str] | None = None) -> int:
    """Standalone entry (``python -m contextrl.experiments.commands``) with the same subcommands."""
    parser = argparse.ArgumentParser(prog="contextrl")
    subparsers = parser.add_subparsers(dest="command", required=True)
    add_run(subparsers)
    add_report(subparsers)
    args = parser.parse_args(argv)
    try:
        return args.handler(args)
    except ValueError as error:
        print(f"contextrl {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
