"""A protocol as the library runs it. Its spec class (plain data and its validation) lives in the
protocol's module; the :class:`Protocol` record names the rest: how a spec expands into context sets
and trials, the report sections it declares and the shared ones it wants, how ``contextrl run
--vary`` sets its spec, and, for a protocol that does not run as chunks of trials, how it runs."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from contextrl.experiments.spec import (
    SPECS,
    CommonSpec,
    SpecError,
    merge_features,
    parse_assignments,
    parse_distribution,
)


def seeds_text(spec: CommonSpec) -> str:
    """What a report's summary says was trained: seeds of every agent."""
    return f"{spec.seeds} seeds (base seed {spec.seed})"


def chunks_progress(spec: CommonSpec, run, plan, results, failures) -> dict:
    """A report's progress row for a run of chunks of trials."""
    return {
        "trials": len(plan.trials),
        "trials finished": int(results["trial"].nunique()) if not results.empty else 0,
        "chunks": len(plan.chunks),
        "chunks finished": len(run.finished()),
        "chunks failed": len(failures),
        "seconds (sum over chunks)": round(sum(run.timings().values()), 1),
    }


@dataclasses.dataclass(frozen=True)
class Protocol:
    """What a protocol adds to its spec class.

    ``sections(spec, plan, results, curves)`` builds the protocol's own report sections (a protocol
    that trains agents gets its results as score cells, :func:`contextrl.analysis.scores.score_cells`,
    so every section reads the same numbers); the report adds the shared ones it asks for around
    them. ``expand(spec)`` returns the named context sets and the trials (None: trains no agents);
    ``outline(spec)`` returns the same trials and each set's size without drawing a context (None:
    counting steps and chunks expands the spec).
    ``vary(data, items)`` applies ``--vary`` items to a spec mapping and returns a notice (None: each
    item is FEATURE=DIST, merged into the spec's ``vary_field``). ``execute(spec, run, plan, *,
    executor, address, max_chunks, progress, verbose) -> Summary`` runs it where it does not run as
    the plan's chunks of trials."""

    spec: type[CommonSpec]
    sections: Callable[..., list]
    expand: Callable[[Any], tuple[dict, list]] | None = None
    outline: Callable[[Any], tuple[dict[str, int], list]] | None = None
    vary: Callable[[dict, list[str]], str | None] | None = None
    execute: Callable[..., Any] | None = None
    runs_on_ray: bool = False  # it starts Ray itself (--address applies)
    per_context_figures: bool = True  # report: return against each varied feature
    # report: the per-context section's interval table (False where the protocol's own section
    # shows the same agents' intervals, so the table is not shown twice)
    per_context_intervals: bool = True
    draws_heatmap: bool = False  # its own sections draw the two-feature heat map
    training_section: bool = True  # report: the training curves (PB2 draws its schedules instead)
    # sections(…, training=) also gets each trial's return on its training contexts and a random
    # policy's there (the verdicts it gives only for agents that learned)
    reads_training: bool = False
    runs_text: Callable[[Any], str] = seeds_text
    progress_row: Callable[..., dict] = chunks_progress

    @property
    def name(self) -> str:
        return self.spec.__dataclass_fields__["protocol"].default

    def vary_spec(self, data: dict, items: list[str]) -> str | None:
        """Apply ``contextrl run --vary`` items to the spec mapping ``data``, feature by feature on
        top of what a config gave; returns a notice saying what was kept and replaced."""
        if self.vary is not None:
            return self.vary(data, items)
        field = self.spec.vary_field
        if field is None:
            raise SpecError(f"--vary: the {self.name} protocol varies no features")
        given = parse_assignments(items, "--vary", "FEATURE=DIST", parse_distribution)
        return merge_features(data, field, given)


PROTOCOLS: dict[str, Protocol] = {}


def register_protocol(protocol: Protocol) -> Protocol:
    """Make ``protocol`` the one named by its spec's ``protocol`` field default (specs name it)."""
    name = protocol.name
    if not isinstance(name, str) or not name:
        raise TypeError(f"{protocol.spec.__name__} needs a default for its protocol field")
    PROTOCOLS[name] = protocol
    SPECS[name] = protocol.spec
    return protocol


def protocol_of(spec: CommonSpec) -> Protocol:
    return PROTOCOLS[spec.protocol]


def protocol_names() -> list[str]:
    return list(PROTOCOLS)
