"""The paper's figures: each one's spec files (``specs/<figure>.yaml``, or one per part for a figure of
several runs, such as PB2 with the context hidden and visible), the check that decides its claim, and
a smaller budget for two CPU cores; a spec at any scale (paper, small, tiny)."""

from __future__ import annotations

import copy
import dataclasses
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from contextrl.agents import ConfigError
from contextrl.experiments.runs import RunDir
from contextrl.experiments.spec import SpecError, load_yaml, parse_spec
from contextrl.paper.checks import (
    GATE,
    MIN_SEEDS,
    Check,
    Verdict,
    better_check,
    gap_check,
    kirk_check,
    sensitivity_check,
    similar_check,
    tabular_check,
)
from contextrl.paper.plans import training_steps

SPEC_FOLDER = Path(__file__).resolve().parent / "specs"
SCALES = ("paper", "small", "tiny")
# A settings line that says the figure's agent stands in for the paper's
SUBSTITUTED = re.compile(r"the paper used|a disclosed deviation from the paper's agent")
CAUSES = (
    "A *not reproduced* names the first of these the runs show as its most likely cause: an agent "
    "at the return ceiling (no room left for the difference the claim needs); a substituted agent "
    "(the figure's settings say its agent stands in for the paper's); a budget below the authors' "
    "(where the spec records theirs); else the budget, chosen here (the figure's budget line says "
    "why), where the spec records none of the authors'."
)


@dataclasses.dataclass(frozen=True)
class PaperFigure:
    """A figure of the paper: its spec file(s), the check of its claim and its small budget."""

    name: str
    check: Check
    small: Mapping[str, Any]  # spec fields for two CPU cores (agent_options merge into the spec's)
    parts: tuple[str, ...] = ()  # spec files (stems) of a figure of several runs
    decided_small: bool = False  # the full budget does not fit two CPU cores: the small run decides

    def files(self) -> dict[str, Path]:
        stems = self.parts or (self.name,)
        return {
            stem.removeprefix(self.name + "_") or stem: SPEC_FOLDER / f"{stem}.yaml"
            for stem in stems
        }

    def header(self, key: str, part: str | None = None) -> str:
        """The ``# Key:`` header of the figure's first spec (or of ``part``), with its
        continuation lines (``# `` lines up to the next key) joined."""
        path = self.files()[part] if part else next(iter(self.files().values()))
        found, inside = [], False
        for line in path.read_text(encoding="utf-8").splitlines():
            if not line.startswith("#"):
                break
            body = line[1:].strip()
            starts = re.match(r"[A-Z][a-z]+:", body)
            if starts:
                inside = body.startswith(f"{key}:")
                body = body[len(key) + 1 :].strip() if inside else body
            if inside:
                found.append(body)
        return " ".join(found)

    @property
    def rule(self) -> str:
        """The decision rule, as the spec's ``# Decision:`` line and the page state it."""
        return self.check.rule + (f" {GATE}" if self.check.gated else "")

    def verdict(self, runs: Mapping[str, RunDir], settled: bool = False) -> Verdict | None:
        """The check's verdict on ``runs`` (``settled``: what the finished chunks of runs under way
        already fix, or None), a claim not reproduced with the budget and settings it was not
        reproduced at and its most likely cause, by the rule CAUSES states."""
        found = self.check.settled(runs) if settled else self.check(runs)
        if found is None or found.withheld or found.holds is not False:
            return found
        specs = {part: run.spec() for part, run in runs.items()}
        steps = sum(training_steps(spec) for spec in specs.values())
        seeds = min(spec.seeds for spec in specs.values())
        agents = " and ".join(sorted({spec.agent for spec in specs.values()}))
        at = f"{steps:,} training steps, {seeds} seeds and the settings stated ({agents})"
        return dataclasses.replace(found, at=at, cause=found.cause or self._cause(specs, steps))

    def _cause(self, specs: Mapping[str, Any], steps: int) -> str:
        """The most likely cause of a claim not reproduced, short of an agent at the ceiling
        (which the check itself sees): a substituted agent, then the budget."""
        settings = " ".join(self.header("Settings", part) for part in specs)
        if SUBSTITUTED.search(settings):
            return "a substituted agent (the settings say which, and why)"
        if not self.stated_budget:
            return "the budget, chosen here (the budget line says why)"
        theirs = sum(training_steps(parse_spec(spec_data(self, p, "paper"))) for p in specs)
        if steps < theirs:
            return f"a budget below the authors' ({steps:,} of their {theirs:,} training steps)"
        return "none the runs show: the budget and settings are the authors'"

    @property
    def stated_budget(self) -> bool:
        """Whether the authors (their experiment configs, or the paper's text) state the budget its
        ``paper`` scale runs (else: a full budget chosen here)."""
        return self.header("Budget").startswith("the authors'")


def _smallest_budget(spec, options: dict) -> int:
    """The smallest power-of-two step budget (from 256) the agent accepts for every variant."""
    budget = 256
    while True:
        try:
            for variant in spec.variants:
                spec.agent_entry().config(spec.env, {**options, "total_timesteps": budget}, variant)
            return budget
        except ConfigError:
            if budget >= 1 << 20:
                raise
            budget *= 2


def _tiny(data: dict) -> dict:
    """A smoke-test budget: every protocol step runs once, in seconds to a minute; decides nothing."""
    spec = parse_spec(data)
    out = copy.deepcopy(data)
    fields = {f.name for f in dataclasses.fields(spec)}
    small = {
        "seeds": 2, "eval_episodes": 1, "max_steps": 20, "num_contexts": 2, "batch_size": 4,
        "num_train_contexts": 4, "num_test_contexts": 4, "population": 2, "rounds": 1,
        "num_random": 1, "magnitudes": [0.5, 1.0], "bootstrap_reps": 50,
    }  # fmt: skip
    out.update({k: v for k, v in small.items() if k in fields and k not in spec.unused_fields})
    if spec.protocol == "sensitivity":
        out["features"] = list(spec.feature_names()[:2])
    if spec.trains_agents:
        names = spec.agent_entry().option_names()
        options = {
            "learning_starts": 32, "num_envs": 2, "num_steps": 16, "batch_size": 16,
            "log_every": 64, "hidden_sizes": [16, 16],
        }  # fmt: skip
        merged = {
            **out.get("agent_options", {}),
            **{k: v for k, v in options.items() if k in names},
        }
        budget = _smallest_budget(spec, merged)
        if spec.protocol == "hpo":  # a member trains steps_per_round steps a round
            out["steps_per_round"] = budget
        else:
            merged["total_timesteps"] = budget
        out["agent_options"] = merged
    return out


def spec_data(figure: PaperFigure, part: str, scale: str) -> dict:
    """The spec of one part of ``figure`` at ``scale`` (paper: the file as it ships)."""
    if scale not in SCALES:
        raise SpecError(f"scale: unknown scale {scale!r}; choose one of {list(SCALES)}")
    path = figure.files()[part]
    data = load_yaml(path.read_text(encoding="utf-8"), str(path))
    if scale == "small":
        for key, value in figure.small.items():
            data[key] = {**data.get(key, {}), **value} if key == "agent_options" else value
    elif scale == "tiny":
        data = _tiny(data)
    data["name"] = f"{data['name']}-{scale}"
    return data


_SMALL_C51 = {"agent_options": {"total_timesteps": 30000}}


_SMALL_SAC = {"agent_options": {"total_timesteps": 20000}}


# A figure whose full budget does not fit two CPU cores in a working session (LunarLander's visibility
# baseline and PB2: hours to days) is decided at the small budget (``decided_small``), which therefore
# trains the fewest seeds a verdict needs (MIN_SEEDS); elsewhere the small budget previews, with 3
# seeds, the full run that decides.
FIGURES = {
    f.name: f
    for f in [
        PaperFigure("tabular_cmdp", tabular_check, {}),
        PaperFigure(
            "ecdf_pendulum",
            sensitivity_check(
                harmless=("initial_angle_max", "initial_velocity_max"),
                brittle=("max_speed", "dt", "g", "l"),
            ),
            {**_SMALL_SAC, "seeds": 3, "eval_episodes": 5},
        ),
        PaperFigure(
            "optgap_cartpole",
            gap_check(30.0, finished=True, most_per_step=1.0),  # CartPole: +1 per step
            {**_SMALL_C51, "num_contexts": 8, "seeds": 3, "batch_size": 9},
        ),
        PaperFigure(
            "optgap_pendulum",
            gap_check(0.0),
            {**_SMALL_SAC, "num_contexts": 8, "seeds": 3, "batch_size": 9},
        ),
        PaperFigure(
            "visibility_dmcwalker",
            better_check("concat_varying", "hidden"),
            {
                "agent_options": {"total_timesteps": 60000},
                "seeds": 2,
                "max_steps": 200,
                "num_test_contexts": 20,
            },
        ),
        PaperFigure(
            "visibility_dmcwalker_table",
            better_check("concat_varying", "hidden"),
            {
                "agent_options": {"total_timesteps": 60000},
                "seeds": 2,
                "max_steps": 200,
                "num_test_contexts": 20,
            },
        ),
        PaperFigure(
            "visibility_dmcwalker_cleanrl",
            better_check("concat_varying", "hidden"),
            {
                "agent_options": {"total_timesteps": 60000},
                "seeds": 2,
                "max_steps": 200,
                "num_test_contexts": 20,
            },
        ),
        PaperFigure(
            "visibility_dmcwalker_tuned_entropy",
            better_check("concat_varying", "hidden"),
            {
                "agent_options": {"total_timesteps": 60000},
                "seeds": 2,
                "max_steps": 200,
                "num_test_contexts": 20,
            },
        ),
        PaperFigure(
            "visibility_pendulum",
            similar_check("concat_varying", "hidden"),
            {**_SMALL_SAC, "seeds": 5, "num_test_contexts": 50, "eval_episodes": 5},
        ),
        *(
            PaperFigure(
                name,
                check,
                {
                    **small,
                    "seeds": 3,
                    "num_train_contexts": 200,
                    "num_test_contexts": 225,
                    "eval_episodes": 2,
                },
            )  # fmt: skip
            for name, check, small in (
                ("kirk_cartpole", kirk_check(concat_extrapolates=True), _SMALL_C51),
                ("kirk_pendulum_gravity_dt", kirk_check(), _SMALL_SAC),
                (
                    "kirk_pendulum_gravity_length",
                    better_check("hidden", "concat_varying"),
                    _SMALL_SAC,
                ),
            )
        ),
        *(
            figure
            for env, small in (
                ("pendulum", _SMALL_SAC),
                ("mountaincar", _SMALL_C51),
                ("cartpole", _SMALL_C51),
                ("acrobot", _SMALL_C51),
                ("lunarlander", _SMALL_C51),
            )
            for figure in (
                PaperFigure(
                    f"baseline_{env}_default",
                    sensitivity_check(),
                    {**small, "seeds": 3, "eval_episodes": 5},
                ),
                PaperFigure(
                    f"baseline_{env}_visibility",
                    # CartPole: +1 a step, so a return of at most the time limit
                    better_check("concat_varying", "hidden", 1.0 if env == "cartpole" else None),
                    {
                        **small,
                        "seeds": MIN_SEEDS if env == "lunarlander" else 3,
                        "num_train_contexts": 32,
                        "num_test_contexts": 32,
                    },
                    decided_small=env == "lunarlander",
                ),
            )
        ),
        *(
            PaperFigure(
                f"ecdf_{env}",
                sensitivity_check(),
                {"agent_options": {"total_timesteps": 20000}, "seeds": 2, "eval_episodes": 2},
            )
            for env in ("bipedalwalker", "dmcfish", "dmcquadruped", "dmcwalker")
        ),
        *(
            PaperFigure(
                f"pb2_{env}",
                better_check("hidden", "concat_all"),
                {"population": 4, "rounds": 4, "steps_per_round": 10000, "seeds": MIN_SEEDS},
                parts=(f"pb2_{env}_hidden", f"pb2_{env}_visible"),
                decided_small=True,
            )
            for env in ("acrobot", "lunarlander", "pendulum")
        ),
        PaperFigure(
            "platformer_conditioning",
            better_check("concat_varying", "hidden"),
            {"agent_options": {"total_timesteps": 500000}, "seeds": 3},
        ),
    ]
}
