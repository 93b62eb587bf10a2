"""Which of the appendix table's SAC settings keeps SAC from learning DmcWalker.

    python benchmarks/sac_dmcwalker_settings.py                      # every row, into runs/sac-dmcwalker
    python benchmarks/sac_dmcwalker_settings.py --only table entropy --markdown out.md

The paper's figure visibility_dmcwalker at its small budget (hidden context, viscosity ~ U(0, 1.5),
128 training contexts, 60,000 steps, 200-step episodes, seeds 0–1), trained with the appendix
table's SAC settings (the spec visibility_dmcwalker_table) and with each of them moved, one at a
time, to CleanRL's default, with CleanRL's defaults throughout, and with the authors' dm_control
config (``sac.paper_config("DmcWalker")``). Each row is a visibility run, on the processes executor, into OUT/<row>; a finished run
is read back, not retrained. The table gives each seed's mean return at its training contexts beside a
random policy's on the same contexts, and whether it beat that by the margin the figures' learnability
gate asks of each variant's mean (:func:`contextrl.analysis.scores.learned`).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from contextrl.xla_flags import xla_cpu_workaround

xla_cpu_workaround()  # before anything starts JAX's CPU backend

from contextrl.agents.sac import SACConfig  # noqa: E402
from contextrl.analysis.scores import learned  # noqa: E402
from contextrl.experiments import RunDir, resume, run_experiment  # noqa: E402
from contextrl.paper.catalogue import FIGURES, spec_data  # noqa: E402

# The appendix table's DmcWalker column and the viscosity drawn, as the spec
# visibility_dmcwalker_table states them
_TABLE_SPEC = spec_data(
    FIGURES["visibility_dmcwalker_table"], "visibility_dmcwalker_table", "paper"
)
TABLE = {k: v for k, v in _TABLE_SPEC["agent_options"].items() if k != "total_timesteps"}
# (row, what changes, SAC options): each row moves one of the table's settings to CleanRL's default.
ONE_CHANGE = [
    ("entropy", "entropy weight tuned (table: fixed at 0.2)", {"autotune": True}),
    ("discount", "discount 0.99 (table: 0.9)", {"gamma": 0.99}),
    ("one_step", "1-step returns (table: 5-step)", {"n_step": 1}),
    ("batch", "batches of 256 (table: 128)", {"batch_size": 256}),
    ("actor_lr", "actor learning rate 3e-4 (table: 1e-3)", {"policy_lr": 3e-4}),
    ("tau", "target update rate 0.005 (table: 0.001)", {"tau": 0.005}),
    ("actor_every_2", "an actor update every 2 (table: every 4)", {"policy_frequency": 2}),
]
# CleanRL's defaults are SACConfig's: every option a row moves, at its class default.
CLEANRL = {key: getattr(SACConfig, key) for _, _, row in ONE_CHANGE for key in row}
ROWS = [
    ("table", "the appendix table's settings", TABLE),
    *((name, words, {**TABLE, **change}) for name, words, change in ONE_CHANGE),
    ("cleanrl", "CleanRL's defaults throughout", {**TABLE, **CLEANRL}),
    ("authors", "the authors' dm_control config (environments/dmc/base.yaml)", {}),
]


def spec(options: dict, timesteps: int) -> dict:
    """visibility_dmcwalker's small budget, hidden context only, with these SAC options."""
    return {
        "protocol": "visibility",
        "env": "DmcWalker",
        "agent": "sac",
        "agent_options": {"total_timesteps": timesteps, **options},
        "variants": ["hidden"],
        "train": _TABLE_SPEC["train"],
        "num_train_contexts": 128,
        "num_test_contexts": 20,
        "seeds": 2,
        "max_steps": 200,
        "eval_episodes": 1,
        "batch_size": 1,  # a seed per chunk: both seeds train at once on the processes executor
    }


def train_row(name: str, options: dict, out: Path, timesteps: int) -> RunDir:
    """The row's run, trained now or finished from its folder."""
    path = out / name
    if path.exists():
        return resume(path, executor="processes")[0]
    return run_experiment(spec(options, timesteps), out=path, executor="processes")[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    names = [name for name, _, _ in ROWS]
    parser.add_argument("--only", nargs="+", choices=names, default=names)
    parser.add_argument("--out", type=Path, default=Path("runs/sac-dmcwalker"))
    parser.add_argument("--timesteps", type=int, default=60_000)
    parser.add_argument("--markdown", type=Path, help="also write the table here")
    args = parser.parse_args()
    load = os.getloadavg()[0]
    lines = [
        "| settings | return at its training contexts, per seed | random policy's | learned |",
        "| --- | --- | --- | --- |",
    ]
    for name, words, options in ROWS:
        if name not in args.only:
            continue
        start = time.perf_counter()
        training = train_row(name, options, args.out, args.timesteps).training().sort_values("seed")
        print(f"done: {name}, {(time.perf_counter() - start) / 60:.1f} min", flush=True)
        trained, random = training["train_return"], training["random_return"]
        verdicts = [learned(t, r) for t, r in zip(trained, random, strict=True)]
        lines.append(
            f"| {words} | {', '.join(f'{v:.1f}' for v in trained)} "
            f"| {', '.join(f'{v:.1f}' for v in random)} "
            f"| {', '.join('yes' if v else 'no' for v in verdicts)} |"
        )
    lines.append(
        f"\nSAC on DmcWalker, {args.timesteps:,} steps, seeds 0–1, {os.cpu_count()} CPU cores; "
        f"load {load:.1f} → {os.getloadavg()[0]:.1f}."
    )
    table = "\n".join(lines)
    print(table)
    if args.markdown:
        args.markdown.write_text(table + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
