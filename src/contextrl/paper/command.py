"""The ``contextrl paper`` subcommand: list the figures, run one (its claim checked), write the page."""

from __future__ import annotations

import argparse
from pathlib import Path

from contextrl.experiments.commands import count
from contextrl.experiments.executors import EXECUTORS
from contextrl.experiments.spec import SpecError
from contextrl.paper.catalogue import FIGURES, SCALES
from contextrl.paper.page import figure_rows, results_page
from contextrl.paper.runs import PAPER_RUNS, kept_runs, run_figure


def paper_command(args: argparse.Namespace) -> int:
    if args.action == "run" and args.figure is None:
        raise SpecError(
            f"paper run: name a figure (contextrl paper run FIGURE); choose one of {list(FIGURES)}"
        )
    if args.action != "run" and args.figure is not None:
        raise SpecError(f"paper {args.action}: takes no figure (got {args.figure!r}); run does")
    if args.runs is None:  # run writes under ./results/paper; list and page read the kept runs
        args.runs = PAPER_RUNS if args.action == "run" else kept_runs(args.action == "page")
    elif args.action != "run" and not Path(args.runs).is_dir():
        raise SpecError(
            f"paper {args.action}: --runs {args.runs} is not a folder; give the folder "
            f"`contextrl paper run --runs` wrote (default ./{PAPER_RUNS})"
        )
    elif args.action == "run" and Path(args.runs).exists() and not Path(args.runs).is_dir():
        raise SpecError(f"paper run: --runs {args.runs} is a file; give a folder to write the runs")
    if args.action == "page" and args.out != "-" and not Path(args.out).parent.is_dir():
        raise SpecError(  # before the page is built: that reads every kept run
            f"paper page: --out {args.out}: no folder {Path(args.out).parent}; create it or pick "
            "another (- prints the page)"
        )
    if args.action == "list":
        for row in figure_rows(args.runs):
            print(f"{row.pop('figure')}  ({row.pop('paper')})\n  claim: {row.pop('claim')}")
            print("  " + "; ".join(f"{k}: {v}" for k, v in row.items()))
        return 0
    if args.action == "page":
        text = results_page(args.runs)
        if args.out == "-":
            print(text)
        else:
            Path(args.out).write_text(text + "\n", encoding="utf-8")
            print(f"wrote {args.out}")
        return 0
    if args.figure not in FIGURES:
        raise SpecError(
            f"paper run: unknown figure {args.figure!r}; choose one of {list(FIGURES)} "
            "(contextrl paper list says what each is)"
        )
    verdict, path = run_figure(
        args.figure,
        args.scale,
        root=args.runs,
        executor=args.executor,
        address=args.address,
        batch_size=args.batch_size,
        progress=not args.quiet,
    )
    print(f"{args.figure} ({args.scale} budget): {verdict.sentence()}. {verdict.evidence}.")
    print(f"report: {path}")
    return 0


def add_paper(subparsers) -> None:
    parser = subparsers.add_parser(
        "paper",
        help="the paper's figures: list them, run one (its claim checked), write the results page",
    )
    parser.add_argument(
        "action", nargs="?", choices=["list", "run", "page"], default="list",
        help="list (default): each figure, its claim and time; run FIGURE; page: docs/paper.md",
    )  # fmt: skip
    parser.add_argument("figure", nargs="?", help="with run: the figure (see contextrl paper list)")
    parser.add_argument(
        "--scale",
        choices=SCALES,
        default="small",
        help="the full budget (the authors' where they state one), the small one two CPU cores afford (default), or tiny (a smoke "
        "run: no verdict from its intervals; a claim solved exactly is decided at every scale)",
    )
    parser.add_argument(
        "--runs",
        help=f"folder of the figures' runs: run writes (default ./{PAPER_RUNS}), list and page "
        f"read (default ./{PAPER_RUNS}, else the repository's)",
    )
    parser.add_argument("--out", default="docs/paper.md", help="with page: the file (- prints)")
    parser.add_argument(
        "--executor",
        choices=list(EXECUTORS),
        help="where chunks run (default: a worker process per core for a host environment, this "
        "process for a JAX one)",
    )
    parser.add_argument("--address", help="with --executor ray: the cluster (default: a local Ray)")
    parser.add_argument(
        "--batch-size",
        type=count,
        help="with run: trials per chunk, trained in one vmapped call on a JAX environment (the "
        "spec's; a GPU takes them all) and one after another on a host one (default 1)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    parser.set_defaults(handler=paper_command)
