"""Run directories: the resolved spec, per-chunk results as Parquet (atomic), failures, checkpoints.

Layout of ``runs/<name>-<time>/``::

    spec.yaml            the resolved spec (a run is rebuilt from it on resume)
    manifest.json        versions, seeds, plan size, start time, seconds spent (after each chunk),
                         the agent settings each variant trains with
    results/chunk-0003.parquet    evaluation rows of the trials of chunk 3
    curves/chunk-0003.parquet     their training curves
    training/chunk-0003.parquet   their return on their training contexts, and a random policy's
    checkpoints/<trial>.npz       trained parameters
    failures/chunk-0003.json      error and traceback of a chunk that raised
    timings.json         seconds per finished chunk
    figures/*.png, report.html

Every file is written to a temporary name in the same folder and renamed into place, so a run killed at
any moment leaves only whole files; a chunk counts as finished when its results file exists.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime
import json
import os
import platform
from importlib import metadata
from pathlib import Path
from typing import Any

import pandas as pd
import yaml

from contextrl.agents import save_checkpoint
from contextrl.core.files import atomic_write
from contextrl.experiments.spec import CommonSpec, load_yaml, parse_spec, spec_to_dict


def write_text(path: Path, text: str) -> Path:
    def write(temporary: str) -> None:
        with open(temporary, "w", encoding="utf-8") as handle:
            handle.write(text)

    return atomic_write(path, write)


def write_parquet(path: Path, frame: pd.DataFrame) -> Path:
    return atomic_write(path, lambda temporary: frame.to_parquet(temporary, index=False))


def versions() -> dict[str, str]:
    """Versions of the packages a result depends on."""
    out = {"python": platform.python_version()}
    for package in ("contextrl", "jax", "jaxlib", "numpy", "gymnasium", "optax", "pandas", "ray"):
        with contextlib.suppress(metadata.PackageNotFoundError):
            out[package] = metadata.version(package)
    return out


@dataclasses.dataclass
class Summary:
    """What an execution did: chunks run, skipped (already finished) and failed."""

    ran: list[int]
    skipped: list[int]
    failed: list[int]
    remaining: list[int]
    seconds: float


def agent_settings(spec: CommonSpec) -> dict[str, dict[str, Any]]:
    """Every field of the agent config each variant trains with (the agent's defaults for the
    environment merged with the spec's options), as JSON stores it: what a kept run was trained
    with, to compare with what the same spec resolves to later."""
    if not getattr(spec, "trains_agents", False):
        return {}
    configs = {variant: spec.agent_config(variant) for variant in spec.variants}
    return json.loads(
        json.dumps(
            {v: dataclasses.asdict(c) for v, c in configs.items() if c is not None}, default=str
        )
    )


class RunDir:
    """One run's folder; knows which chunks are finished and reads the results back."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)

    @staticmethod
    def new_path(
        spec: CommonSpec, root: str | os.PathLike = "runs", out: str | None = None
    ) -> Path:
        """Where :meth:`create` puts a new run (``out``, or ``root/<name>-<UTC time>``), refusing an
        ``out`` that holds a run or is a file; nothing is written (a dry run checks the same)."""
        if out is not None:
            path = Path(out)
            if (path / "spec.yaml").exists():
                raise FileExistsError(
                    f"{path} already holds a run; resume it with --resume {path} or pick a new --out"
                )
            if path.exists() and not path.is_dir():
                raise FileExistsError(
                    f"--out {path}: expected a folder for the run, but a file has that name; "
                    f"pick a new folder, e.g. --out {path.parent / (path.stem + '-run')}"
                )
        else:
            stamp = datetime.datetime.now(datetime.UTC).strftime("%Y%m%d-%H%M%S")
            path = Path(root) / f"{spec.name}-{stamp}"
            suffix = 1
            while path.exists():
                suffix += 1
                path = Path(root) / f"{spec.name}-{stamp}-{suffix}"
        return path

    @classmethod
    def create(cls, spec: CommonSpec, root: str | os.PathLike = "runs", out: str | None = None):
        """A new run folder (``out``, or ``root/<name>-<UTC time>``) holding the spec and manifest."""
        path = cls.new_path(spec, root, out)
        run = cls(path)
        path.mkdir(parents=True, exist_ok=True)
        write_text(path / "spec.yaml", yaml.safe_dump(spec_to_dict(spec), sort_keys=False))
        manifest = {
            "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
            "versions": versions(),
            "platform": platform.platform(),
            "agent_settings": agent_settings(spec),
        }
        write_text(path / "manifest.json", json.dumps(manifest, indent=2))
        return run

    def spec(self) -> CommonSpec:
        """The run's spec, re-validated."""
        file = self.path / "spec.yaml"
        if not file.exists():
            raise FileNotFoundError(f"{self.path} is not a run directory (no spec.yaml)")
        return parse_spec(load_yaml(file.read_text(encoding="utf-8"), str(file)))

    def manifest(self) -> dict[str, Any]:
        file = self.path / "manifest.json"
        return json.loads(file.read_text()) if file.exists() else {}

    def update_manifest(self, **values: Any) -> None:
        manifest = self.manifest()
        manifest.update(values)
        write_text(self.path / "manifest.json", json.dumps(manifest, indent=2, default=str))

    def result_path(self, chunk: int) -> Path:
        return self.path / "results" / f"chunk-{chunk:04d}.parquet"

    def finished(self) -> set[int]:
        """Chunks whose results are on disk (temporary leftovers of a crash do not count)."""
        folder = self.path / "results"
        if not folder.exists():
            return set()
        return {int(p.stem.split("-")[1]) for p in folder.glob("chunk-*.parquet")}

    def save_chunk(self, chunk: int, result, trial_ids: list[str], save_params: bool) -> None:
        """Write a finished chunk: checkpoints and curves first, the results file last (the marker)."""
        if save_params:
            for trial_id, params in zip(trial_ids, result.params, strict=True):
                if params is not None:
                    save_checkpoint(
                        self.path / "checkpoints" / f"{trial_id}.npz",
                        params,
                        trial=trial_id,
                        **result.checkpoint,
                    )
        if len(result.curves):
            write_parquet(self.path / "curves" / f"chunk-{chunk:04d}.parquet", result.curves)
        if len(result.training):
            write_parquet(self.path / "training" / f"chunk-{chunk:04d}.parquet", result.training)
        self.record_timing(chunk, result.seconds)
        with contextlib.suppress(FileNotFoundError):
            (self.path / "failures" / f"chunk-{chunk:04d}.json").unlink()
        write_parquet(self.result_path(chunk), result.evaluations)

    def record_timing(self, chunk: int, seconds: float) -> None:
        timings = self.timings()
        timings[str(chunk)] = seconds
        write_text(self.path / "timings.json", json.dumps(timings, indent=2))

    def record_failure(self, chunk: int, trial_ids: list[str], error: str, traceback: str) -> None:
        record = {"chunk": chunk, "trials": trial_ids, "error": error, "traceback": traceback}
        write_text(self.path / "failures" / f"chunk-{chunk:04d}.json", json.dumps(record, indent=2))

    def failures(self) -> list[dict[str, Any]]:
        folder = self.path / "failures"
        if not folder.exists():
            return []
        return [json.loads(p.read_text()) for p in sorted(folder.glob("chunk-*.json"))]

    def timings(self) -> dict[str, float]:
        file = self.path / "timings.json"
        return json.loads(file.read_text()) if file.exists() else {}

    def _read(self, folder: str) -> pd.DataFrame:
        files = sorted((self.path / folder).glob("chunk-*.parquet"))
        if not files:
            return pd.DataFrame()
        frame = pd.concat([pd.read_parquet(f) for f in files], ignore_index=True)
        return frame

    def results(self) -> pd.DataFrame:
        """Every finished evaluation row, sorted by trial and context (independent of finish order)."""
        frame = self._read("results")
        if frame.empty:
            return frame
        return frame.sort_values(["trial", "test_set", "context_index"], ignore_index=True)

    def training(self) -> pd.DataFrame:
        """Per trial: return on its training contexts and a random policy's on the same contexts."""
        frame = self._read("training")
        return frame if frame.empty else frame.sort_values("trial", ignore_index=True)

    def curves(self) -> pd.DataFrame:
        frame = self._read("curves")
        if frame.empty:
            return frame
        return frame.sort_values(["trial", "step"], ignore_index=True)
