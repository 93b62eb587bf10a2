"""Running a figure and reading its runs back: ``contextrl paper run`` writes each part to
``<root>/<figure>-<scale>/<part>`` and the figure's own report (``paper.html``: the claim, the verdict,
the parts' figures), and records the wall time and machine, from which the catalogue's estimates are
extrapolated."""

from __future__ import annotations

import dataclasses
import platform
import sys
import time
from collections.abc import Mapping
from pathlib import Path

import jax

from contextrl.analysis.report import Figure as ReportFigure
from contextrl.analysis.report import Section, render
from contextrl.experiments.executors import usable_cores
from contextrl.experiments.more_seeds import add_seeds
from contextrl.experiments.planning import duration
from contextrl.experiments.runner import run_experiment
from contextrl.experiments.runs import RunDir, write_text
from contextrl.experiments.spec import CommonSpec, SpecError, parse_spec, spec_to_dict
from contextrl.paper.catalogue import FIGURES, PaperFigure, spec_data
from contextrl.paper.checks import Verdict
from contextrl.paper.plans import outlined, parsed_spec, training_steps

PAPER_RUNS = "results/paper"


# The repository's kept runs, where the package is installed from a checkout (editable)
REPOSITORY_RUNS = Path(__file__).resolve().parents[3] / PAPER_RUNS


def kept_runs(required: bool = True) -> Path:
    """Where ``contextrl paper list|page`` reads runs when not told: ./results/paper, else the
    repository's (a checkout the package is installed from); when neither holds runs, refused,
    saying where it looked, or (not ``required``: a listing, whose estimates then say "not
    measured") ./results/paper."""
    for folder in (Path(PAPER_RUNS), REPOSITORY_RUNS):
        if any(folder.glob("*/*/spec.yaml")):
            return folder
    if not required:
        return Path(PAPER_RUNS)
    raise SpecError(
        f"contextrl paper: no runs in ./{PAPER_RUNS} or {REPOSITORY_RUNS}; give --runs FOLDER "
        "(the repository keeps its runs in results/paper; contextrl paper run writes new ones)"
    )


def figure_folder(root: str | Path, name: str, scale: str) -> Path:
    return Path(root) / f"{name}-{scale}"


def started_runs(figure: PaperFigure, root: str | Path, scale: str) -> dict[str, RunDir] | None:
    """The figure's runs at ``scale`` under ``root`` when every part has started (its spec)."""
    runs = {part: RunDir(figure_folder(root, figure.name, scale) / part) for part in figure.files()}
    if not all((run.path / "spec.yaml").exists() for run in runs.values()):
        return None
    return runs


def finished_runs(figure: PaperFigure, root: str | Path, scale: str) -> dict[str, RunDir] | None:
    """The figure's runs at ``scale`` under ``root`` when every part has all its results."""
    runs = started_runs(figure, root, scale)
    for run in (runs or {}).values():
        plan = outlined(run.spec())
        if run.results().empty or len(run.finished()) < max(len(plan.chunks), 1):
            return None
    return runs


def wall_seconds(run: RunDir) -> float:
    """Seconds the run took: its executors' time over every invocation up to the last finished
    chunk (kept by the run itself, so a run stopped and carried on later counts them all), else the
    time ``contextrl paper run`` spent on it (a protocol with its own schedule), else its chunks'
    summed seconds."""
    manifest = run.manifest()
    fallback = manifest.get("paper_wall_seconds", sum(run.timings().values()))
    return float(manifest.get("wall_seconds", fallback))


def machine() -> str:
    """What trained, for the wall times the page states: JAX's accelerator, else the CPU cores, and
    the CPU's model (the same chunk has taken twice as long on one CPU core as on another)."""
    device = jax.devices()[0]
    count = usable_cores()
    cores = f"{count} CPU core{'s' if count > 1 else ''}"
    model = cpu_model()
    cores = f"{cores}, {model}" if model else cores
    return cores if device.platform == "cpu" else f"one {device.device_kind} and {cores}"


def cpu_model(cpuinfo: str | Path = "/proc/cpuinfo") -> str:
    """The CPU's model as Linux names it and its widest vector unit (``AMD EPYC with AVX2``); the
    platform's processor name where there is no ``/proc/cpuinfo``."""
    try:
        lines = Path(cpuinfo).read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return platform.processor()
    fields = {}
    for line in lines:
        key, _, value = line.partition(":")
        fields.setdefault(key.strip(), value.strip())
    name = fields.get("model name", "")
    if not name:
        return ""
    flags = fields.get("flags", "").split()
    vectors = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else ""
    return f"{name} with {vectors}" if vectors else name


def _new_part(figure: PaperFigure, part: str, scale: str, batch_size: int | None) -> dict:
    """The spec a part not yet started runs: the catalogue's, with ``batch_size`` trials per chunk
    where given. A host environment's trials train one after another whatever the chunk, so there
    each trial is its own chunk unless the spec or ``batch_size`` says otherwise: a run stopped
    part-way loses at most the trials under way, and every worker process gets one."""
    data = spec_data(figure, part, scale)
    if batch_size is None and "batch_size" not in data:
        spec = parse_spec(data)
        batch_size = 1 if spec.trains_agents and spec.host else None
    if batch_size is not None:
        data["batch_size"] = batch_size
    return data


def run_figure(
    name: str,
    scale: str = "small",
    *,
    root: str | Path = PAPER_RUNS,
    executor: str | None = None,
    address: str | None = None,
    batch_size: int | None = None,
    progress: bool = True,
) -> tuple[Verdict, Path]:
    """Run (or finish) every part of a figure at ``scale``, then write the figure's report
    (``paper.html``: the claim, the verdict and the parts' figures); returns the verdict and it.
    ``executor`` defaults to one worker process per core for a host environment (its simulator
    runs one copy per process) and to this process for a JAX one; ``batch_size`` sets how many
    trials a new part trains in one vmapped call (a GPU takes all)."""
    figure = FIGURES[name]
    folder = figure_folder(root, name, scale)
    for part in figure.files():
        _add_catalogue_seeds(figure, part, scale, RunDir(folder / part), progress)
    if progress:
        print(plan_text(figure, scale, root, batch_size), file=sys.stderr, flush=True)
    for part in figure.files():
        path = folder / part
        start = time.perf_counter()
        resumed = (path / "spec.yaml").exists()  # then finish it as its own spec.yaml says
        data = None if resumed else _new_part(figure, part, scale, batch_size)
        spec = RunDir(path).spec() if resumed else parse_spec(data)
        host = spec.trains_agents and spec.host  # the tabular protocol has no environment
        options = {
            "executor": executor or ("processes" if host else "local"),
            "address": address,
            "progress": progress,
        }
        if resumed:
            run, summary = run_experiment(resume=path, **options)
        else:
            run, summary = run_experiment(data, out=path, **options)
        spent = time.perf_counter() - start
        kept = run.manifest()
        here = machine()
        trained_on = set(kept.get("paper_machines", [kept.get("paper_machine", here)]))
        run.update_manifest(
            paper_wall_seconds=kept.get("paper_wall_seconds", 0.0) + spent,
            paper_machine=here,
            paper_machines=sorted(trained_on | ({here} if summary.ran else set())),
        )
    runs = finished_runs(figure, root, scale)
    if runs is None:
        raise RuntimeError(f"{name}: some chunks failed; rerun the same command to retry them")
    verdict = figure.verdict(runs)
    return verdict, write_text(folder / "paper.html", _figure_report(figure, scale, runs, verdict))


def _add_catalogue_seeds(
    figure: PaperFigure, part: str, scale: str, run: RunDir, progress: bool
) -> None:
    """Give a kept run the catalogue's seed count where that is larger and nothing else differs
    (the trials per chunk aside): its finished seeds stay (``more_seeds``)."""
    if not (run.path / "spec.yaml").exists():
        return
    kept = spec_to_dict(run.spec())
    wanted = spec_to_dict(parse_spec(spec_data(figure, part, scale)))
    if wanted["seeds"] <= kept["seeds"] or any(
        kept[key] != wanted[key] for key in kept.keys() - {"seeds", "batch_size"}
    ):
        return
    add_seeds(run, wanted["seeds"])
    if progress:
        print(
            f"{part}: seeds {kept['seeds']} -> {wanted['seeds']} as the catalogue's {scale} "
            f"budget says; its {len(run.finished())} finished chunk(s) stay",
            file=sys.stderr,
            flush=True,
        )


def _figure_report(figure: PaperFigure, scale: str, runs: Mapping[str, RunDir], verdict) -> str:
    text = [
        f"The paper ({figure.header('Paper')}): {figure.header('Claim')}",
        f"Decision rule: {figure.rule}",
        f"Here, at the {scale} budget: {verdict.sentence()}. {verdict.evidence}.",
    ]
    rows = [
        {
            "part": part,
            "training steps": f"{training_steps(run.spec()):,}",
            "time": duration(wall_seconds(run)),
            "report": str(Path(part) / "report.html"),
        }
        for part, run in runs.items()
    ]
    figures = [
        ReportFigure(f"{part}-{png.stem}", png.read_bytes(), f"{part}: {png.stem}")
        for part, run in runs.items()
        for png in sorted((run.path / "figures").glob("*.png"))
    ]
    sections = [Section("The paper's claim and ours", text, [("Runs", rows)], figures)]
    return render(f"contextrl paper: {figure.name} ({scale})", sections, {"scale": scale})


def machines(runs) -> str:
    """Where ``runs`` trained, as their manifests say: every machine that ran some of their chunks
    (a run kept before machines were listed names the last one) and JAX's version."""
    named = set()
    for manifest in (run.manifest() for run in runs):
        jax_version = manifest["versions"]["jax"]
        listed = manifest.get("paper_machines", [manifest["paper_machine"]])
        named |= {f"{where} (JAX {jax_version})" for where in listed}
    return " and ".join(sorted(named))


def estimate(figure: PaperFigure, scale: str, root: str | Path) -> str:
    """Wall time of ``figure`` at ``scale`` and where: measured when it ran under ``root``, else
    extrapolated from the seconds per training step of finished runs with the same environment and
    agent (those at ``scale``, else at the small scale), that rate stated, else "not measured"."""
    runs = finished_runs(figure, root, scale)
    if runs is not None:
        return (
            f"{duration(sum(wall_seconds(r) for r in runs.values()))} on {machines(runs.values())}"
        )
    specs = [parse_spec(spec_data(figure, part, scale)) for part in figure.files()]
    rate = seconds_per_step(specs, scale, root)
    steps = sum(training_steps(spec) for spec in specs)
    if rate is None or not steps:
        return "not measured"
    return f"≈ {duration(steps * rate[0])} on {rate[1]} ({per_step(rate[0])} per training step)"


def per_step(seconds: float) -> str:
    """Seconds per training step, readably (``0.42 ms``, ``31 µs``)."""
    return f"{seconds * 1e3:.3g} ms" if seconds >= 1e-3 else f"{seconds * 1e6:.3g} µs"


def seconds_per_step(specs, scale: str, root: str | Path) -> tuple[float, str] | None:
    """Wall seconds per training step of the finished paper runs under ``root`` with the
    environments and agents of ``specs`` and the machines they ran on (saying so where their agent
    settings differ from ``specs``'); None when there are none.
    Runs whose agents have the same settings apart from the budget come first (another agent's batch
    size or update rate can change the cost of a step several times over), those at ``scale`` before
    those at the small scale."""
    wanted = {_agent_settings(spec) for spec in specs}
    agents = {settings[:2] for settings in wanted}
    finished = {measured_scale: [] for measured_scale in (scale, "small")}
    for measured_scale, runs in finished.items():
        for spec_file in sorted(Path(root).glob(f"*-{measured_scale}/*/spec.yaml")):
            run = RunDir(spec_file.parent)
            spec = parsed_spec(spec_file.read_text(encoding="utf-8"))
            settings = _agent_settings(spec)
            if settings[:2] not in agents or "paper_machine" not in run.manifest():
                continue  # another environment or agent, or its `contextrl paper run` never ended
            steps = trained_steps(run, spec)
            if steps:
                runs.append((run, steps, settings))
    for same_settings in (True, False):
        for runs in finished.values():
            measured = [
                (run, steps)
                for run, steps, settings in runs
                if settings in wanted or not same_settings
            ]
            if measured:
                seconds = sum(wall_seconds(run) for run, _ in measured)
                total = sum(steps for _, steps in measured)
                where = machines(run for run, _ in measured)
                other = "" if same_settings else ", from runs of other agent settings"
                return seconds / total, where + other
    return None


def trained_steps(run: RunDir, spec) -> int:
    """Training steps of the run's finished chunks: the time a run under way (a full run stopped
    part-way, or one given more seeds) has spent trained these, not its whole plan."""
    return spec.training_steps(_trials_of(outlined(spec), run.finished()))


def _trials_of(plan, chunks: set[int]) -> list:
    """The trials of a plan (or its outline) in the chunks numbered ``chunks``."""
    return [plan.trials[i] for n, chunk in enumerate(plan.chunks) if n in chunks for i in chunk]


def _agent_settings(spec) -> tuple[str, str, str]:
    """The environment, the agent and its options other than the budget, comparable as text. A PB2
    population's members train one to a process, not many in one vmapped call, so they count as an
    agent of their own: a step costs them another time."""
    options = {k: v for k, v in spec.agent_options.items() if k != "total_timesteps"}
    agent = f"{spec.agent} in PB2" if spec.protocol == "hpo" else spec.agent
    return spec.env, agent, repr(sorted(options.items()))


@dataclasses.dataclass(frozen=True)
class PartProgress:
    """How far one part of a figure has run: its chunks and training steps, in all and left."""

    part: str
    spec: CommonSpec
    trials: int
    chunks: int
    finished: int
    steps: int
    steps_left: int


def progress(
    figure: PaperFigure, scale: str, root: str | Path, batch_size: int | None = None
) -> list[PartProgress]:
    """Each part's progress under ``root``: from its run's own spec and finished chunks, else (not
    started) from the catalogue's spec with ``batch_size`` trials per chunk."""
    parts = []
    for part in figure.files():
        run = RunDir(figure_folder(root, figure.name, scale) / part)
        if (run.path / "spec.yaml").exists():
            spec, done = run.spec(), run.finished()
        else:
            spec, done = parse_spec(_new_part(figure, part, scale, batch_size)), set()
        plan = outlined(spec)
        left = set(range(len(plan.chunks))) - done
        parts.append(
            PartProgress(
                part,
                spec,
                len(plan.trials),
                len(plan.chunks),
                len(done),
                spec.training_steps(plan.trials),
                spec.training_steps(_trials_of(plan, left)),
            )
        )
    return parts


def time_left(figure: PaperFigure, parts: list[PartProgress], scale: str, root: str | Path) -> str:
    """The time the parts' steps left should take at the pace of the figure's own finished chunks
    (this budget, these settings: a host figure's evaluation grows with its episodes' length; the
    machines named where recorded), else at the rate finished runs of the same agents were
    measured at."""
    left = sum(p.steps_left for p in parts)
    if not left:
        return "nothing left to train"
    done = sum(p.steps - p.steps_left for p in parts)
    folder = figure_folder(root, figure.name, scale)
    runs = [RunDir(folder / p.part) for p in parts if p.finished]
    if done and runs:
        seconds = sum(wall_seconds(run) for run in runs)
        where = machines(run for run in runs if "paper_machine" in run.manifest())
        on = f" (on {where})" if where else ""
        return f"≈ {duration(left * seconds / done)} at the pace of its finished chunks{on}"
    rate = seconds_per_step([p.spec for p in parts], scale, root)
    if rate is not None:
        return f"≈ {duration(left * rate[0])} at the rate measured on {rate[1]}"
    return "not estimated (no finished run of these agents)"


def plan_text(
    figure: PaperFigure, scale: str, root: str | Path, batch_size: int | None = None
) -> str:
    """What ``contextrl paper run`` is about to do: per part, its trials and chunks, those already
    finished, the training steps left, and the time they should take at the measured rate."""
    lines = [
        f"{figure.name} at the {scale} budget, into {figure_folder(root, figure.name, scale)}:"
    ]
    parts = progress(figure, scale, root, batch_size)
    for p in parts:
        lines.append(
            f"  {p.part}: {p.trials} trials in {p.chunks} chunk(s) of up to "
            f"{p.spec.batch_size}, {p.finished} finished; {p.steps_left:,} of {p.steps:,} "
            "training steps left"
        )
    lines.append(f"  time left: {time_left(figure, parts, scale, root)}; this machine: {machine()}")
    return "\n".join(lines)
