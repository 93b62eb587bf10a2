"""The hpo protocol: tune an agent's hyper-parameters on a context distribution with population-based
bandits (PB2, Parker-Holder et al. 2020) on Ray Tune, as the paper tunes its agents.

A population of agents trains on contexts drawn from ``train``; every round (``steps_per_round``
environment steps) each member reports its mean return on the training contexts, and PB2 replaces the
worst members by copies of the best with hyper-parameters chosen by a time-varying GP bandit within
``search`` bounds. Members continue training their parameters (with a fresh optimiser) across rounds,
compiled on a JAX environment and through the shared host collector on a host one.
The run keeps each member's hyper-parameter schedule, writes ``best.yaml`` (the best member's final
agent options, for ``contextrl run ... --agent-config best.yaml``) and evaluates the best member on the
test contexts. ``seeds`` runs PB2 that many times from base seeds ``seed``, ``seed + 1``, ... on the
same contexts (each run a chunk: written, resumed and counted as one seed by the statistics, so a claim
about what PB2 finds rests on several searches); runs after the first write ``best-s1.yaml``, ...
Ray runs locally by default, or on a cluster (``--address``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import random
import sys
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path

import jax
import numpy as np
import pandas as pd
import yaml

from contextrl.agents import ConfigError, evaluate, get_agent, load_checkpoint, save_checkpoint
from contextrl.analysis import metrics, plots
from contextrl.analysis.report import Section
from contextrl.analysis.scores import score_matrices
from contextrl.compile_cache import use_compilation_cache
from contextrl.experiments.plan import TEST_KEY, Trial, train_and_test_sets, train_and_test_sizes
from contextrl.experiments.protocol import Protocol, register_protocol
from contextrl.experiments.ray_cluster import start_ray
from contextrl.experiments.ray_output import ray_output_to
from contextrl.experiments.reports import figure
from contextrl.experiments.runs import Summary, write_parquet, write_text
from contextrl.experiments.spec import (
    MAX_INT32,
    CommonSpec,
    SpecError,
    check_int,
    check_number,
    parse_spec,
    spec_to_dict,
)
from contextrl.experiments.trials import host_context_input, host_returns

# Searched when ``search`` is empty: the step sizes and the agent's main trade-off.
DEFAULT_SEARCH = {
    "ppo": {"learning_rate": [1e-5, 1e-2], "ent_coef": [0.0, 0.05], "clip_eps": [0.1, 0.4]},
    "sac": {"policy_lr": [1e-5, 1e-2], "q_lr": [1e-5, 1e-2], "tau": [1e-3, 0.05]},
    "dqn": {"learning_rate": [1e-5, 1e-2], "tau": [1e-3, 1.0]},
    "c51": {"learning_rate": [1e-5, 1e-2], "tau": [1e-3, 1.0]},
}
BEST_FILE = "best.yaml"
# What tracing a hyper-parameter raises where an agent needs its value in Python (a shape, a branch).
TRACING_ERRORS = (
    jax.errors.ConcretizationTypeError,
    jax.errors.TracerIntegerConversionError,
    jax.errors.TracerArrayConversionError,
)


@dataclasses.dataclass(frozen=True)
class HPOSpec(CommonSpec):
    """PB2 over ``search`` (hyper-parameter → [low, high]) with a population trained on ``train``."""

    protocol: str = "hpo"
    train: dict | None = None  # None: the environment's default (spec.ENV_DEFAULTS)
    env_defaults = ("train",)
    test: dict | None = None  # None: held-out contexts from the training distribution
    num_train_contexts: int = 64
    num_test_contexts: int = 64
    search: dict = dataclasses.field(default_factory=dict)  # {}: DEFAULT_SEARCH of the agent
    population: int = 4
    rounds: int = 8
    steps_per_round: int = 20_000
    # Each round trains with the rate PB2 set for it; true: PPO anneals it to 0 within every round.
    anneal_per_round: bool = False
    seeds: int = 1  # PB2 runs, one after another (each a population)
    batch_size: int = 1  # one PB2 run per chunk

    unused_fields = {"batch_size": "trains each member on its own Ray worker"}

    def training_steps(self, trials) -> int:
        return len(trials) * self.population * self.rounds * self.steps_per_round

    def budget_note(self) -> None:
        """None: a member's budget is rounds × steps_per_round, not the agent's total_timesteps
        (which the shared note reads)."""
        return None

    def validate(self) -> None:
        super().validate()
        for field in ("num_train_contexts", "num_test_contexts", "population", "rounds"):
            check_int(field, getattr(self, field), 1)
        check_int("steps_per_round", self.steps_per_round, 1, MAX_INT32)
        if "total_timesteps" in self.agent_options:
            raise SpecError(
                "agent_options.total_timesteps: hpo trains each member for rounds × steps_per_round "
                f"steps ({self.rounds} × {self.steps_per_round} here), so --timesteps and "
                "total_timesteps do not apply; set the budget with --set rounds=N and "
                "--set steps_per_round=N"
            )
        if len(self.variants) != 1:
            raise SpecError(
                f"variants: hpo tunes one visibility variant, got {list(self.variants)}"
            )
        if not isinstance(self.anneal_per_round, bool):
            raise SpecError(
                f"anneal_per_round: expected true or false, got {self.anneal_per_round!r}"
            )
        annealing = "anneal_lr" in self.agent_entry().option_names()
        if "anneal_lr" in self.agent_options:
            raise SpecError(
                "agent_options.anneal_lr: hpo trains each round with the learning rate PB2 sets for "
                "it (a restarted schedule would decay it to 0 every round); --set "
                "anneal_per_round=true anneals it within each round"
            )
        if self.anneal_per_round and not annealing:
            raise SpecError(
                f"anneal_per_round: the {self.agent} agent has no learning-rate annealing"
            )
        if self.population < 2:
            raise SpecError(f"population: PB2 needs at least 2 members, got {self.population}")
        if self.seed + self.seeds - 1 > 2**32 - 1:
            raise SpecError(
                f"seeds: {self.seeds} PB2 searches take base seeds {self.seed} to "
                f"{self.seed + self.seeds - 1}, past the largest seed 2**32 - 1; lower seed or seeds"
            )
        if not self.agent_entry().trained:
            raise SpecError(f"hpo tunes a trained agent; {self.agent} does not learn")
        self.resolve_features("train", self.train)
        if self.test is not None:
            self.resolve_features("test", self.test)
        bounds = self.bounds()
        options = self.agent_entry().option_names()
        for name, (low, high) in bounds.items():
            if name not in options:
                raise SpecError(f"search: {name!r} is not a {self.agent} option; valid: {options}")
            check_number(f"search.{name}", low)
            check_number(f"search.{name}", high)
            if not low < high:
                raise SpecError(f"search.{name}: empty range [{low}, {high}]")
            for value in (low, high):
                self._config({name: value})  # each bound must be a valid setting

    def bounds(self) -> dict[str, tuple[float, float]]:
        search = self.search or DEFAULT_SEARCH.get(self.agent, {})
        if not isinstance(search, Mapping) or not search:
            raise SpecError(
                f"search: give hyper-parameter bounds {{name: [low, high]}} for {self.agent}"
            )
        out = {}
        for name, ends in search.items():
            if not isinstance(ends, (list, tuple)) or len(ends) != 2:
                raise SpecError(f"search.{name}: give [low, high], got {ends!r}")
            out[name] = (ends[0], ends[1])
        return out

    def _config(self, hyper: Mapping[str, float]):
        options = {**self.agent_options, **hyper, "total_timesteps": self.steps_per_round}
        if "anneal_lr" in self.agent_entry().option_names():
            options["anneal_lr"] = self.anneal_per_round
        try:
            return self.agent_entry().config(self.env, options, self.variants[0])
        except ConfigError as error:
            raise SpecError(f"search: {error}") from None


def _trainable(config: dict) -> None:
    """One population member on a Ray worker: train a round, report, checkpoint, repeat.

    Its keys come from the spec's seed, its member index and the round, so a rerun trains the same.
    Synchronous PB2 pauses every member at every round and restarts it from its checkpoint; Ray
    reuses the worker processes (``reuse_actors``: no new Python, JAX and Ray imports per round), and
    compiled functions go to the persistent JAX cache (contextrl.compile_cache), so a restarted
    member reads its compiled training instead of compiling it again.
    """
    from ray import tune  # optional and slow to import: only the hpo protocol loads it

    use_compilation_cache()
    spec = parse_spec(config["spec"])
    env = spec.make_env()
    train_set = _expand(spec)[0]["train"].contexts
    agent = spec.agent_entry()
    hyper = {name: config[name] for name in spec.bounds()}
    agent_config = spec._config(hyper)
    train = _round_trainer(spec, env, agent_config, train_set)
    returns = _evaluator(spec, env, agent_config, train_set)
    init_key, key = jax.random.split(
        jax.random.fold_in(jax.random.key(spec.seed + config["run"]), config["member"])
    )
    params, round_index = None, 0
    checkpoint = tune.get_checkpoint()
    if checkpoint is not None:
        with checkpoint.as_directory() as folder:
            params = load_checkpoint(Path(folder) / "params.npz")
            round_index = int((Path(folder) / "round").read_text())
    elif agent.init_params is not None and not spec.host:  # else the first round initialises
        params = agent.init_params(agent_config, env, train_set, init_key)
    while True:
        round_key = jax.random.fold_in(key, round_index)
        train_key, eval_key = jax.random.split(round_key)
        params = train(train_key, params)
        round_index += 1
        mean_return = float(returns(params, train_set, eval_key).mean())
        with tempfile.TemporaryDirectory() as folder:
            save_checkpoint(Path(folder) / "params.npz", params)
            (Path(folder) / "round").write_text(str(round_index))
            tune.report(
                {
                    "return": mean_return,
                    "env_steps": round_index * spec.steps_per_round,
                    **{f"hp/{name}": float(value) for name, value in hyper.items()},
                },
                checkpoint=tune.Checkpoint.from_directory(folder),
            )


def _round_trainer(spec: HPOSpec, env, config, train_set):
    """``train(key, params) -> params``: one round of training that continues ``params`` (None: fresh
    ones), compiled on a JAX environment, on the shared host collector otherwise."""
    agent = spec.agent_entry()
    if not spec.host:
        return _compiled_round(agent, config, env, train_set, list(spec.bounds()))
    context = host_context_input(spec, spec.variants[0], env, train_set)
    limit = {} if spec.max_steps is None else {"max_steps": spec.max_steps}

    def train(key, params):
        seed = int(jax.random.randint(key, (), 0, 2**31 - 1))
        result = agent.train_host(
            config,
            spec.env,
            train_set,
            key,
            seed=seed,
            init_params=params,
            context=context,
            **limit,
        )
        return result.params

    return train


def _compiled_round(agent, config, env, train_set, searched: list[str]):
    """One round of compiled training in which the searched float hyper-parameters are inputs, not
    constants: every member and every round runs one program, compiled once and read from the
    persistent cache by the members Ray restarts (with constants, each member's new values meant a
    new compilation). Where the agent uses a searched value outside arithmetic (a shape, a Python
    branch), tracing it fails and that hyper-parameter stays a constant."""
    traced = {
        name: getattr(config, name) for name in searched if isinstance(getattr(config, name), float)
    }

    def train_round(key, params, hyper):
        make_train = agent.make_train(dataclasses.replace(config, **hyper), env, train_set)
        return make_train(key, None, params).params

    compiled = jax.jit(train_round)
    constant = jax.jit(lambda key, params: train_round(key, params, {}))

    use_traced = True

    def train(key, params):
        nonlocal use_traced
        if use_traced:
            try:
                return compiled(key, params, traced)
            except (*TRACING_ERRORS, ConfigError):  # raised while tracing, before anything ran
                use_traced = False  # later rounds in this process go straight to the constants
        return constant(key, params)

    return train


def _evaluator(spec: HPOSpec, env, config, train_set, agent: str | None = None):
    """``returns(params, contexts, key) -> mean return per context`` of ``agent`` (default: the
    spec's) trained on ``train_set``: compiled on a JAX environment, in host copies otherwise."""
    entry = get_agent(agent or spec.agent)
    if not spec.host:
        policy = entry.make_policy(config, env, train_set)
        run = jax.jit(lambda p, c, k: evaluate(policy, p, env, c, spec.eval_episodes, k))
        return lambda params, contexts, key: np.asarray(run(params, contexts, key))
    context = host_context_input(spec, spec.variants[0], env, train_set)
    act = jax.jit(entry.make_policy(config, env, train_set).act)

    def returns(params, contexts, key):
        return host_returns(spec, context, act, params, contexts, spec.eval_episodes, key)

    return returns


@contextlib.contextmanager
def _global_generators_seeded(seed: int):
    """Python's and numpy's global generators seeded with ``seed`` inside, restored after: Ray's
    PB2 draws from them and takes no seed."""
    python_state, numpy_state = random.getstate(), np.random.get_state()
    random.seed(seed)
    np.random.seed(seed)
    try:
        yield
    finally:
        random.setstate(python_state)
        np.random.set_state(numpy_state)


def seeded_pb2(seed: int, **options):
    """Ray Tune's PB2 made reproducible from ``seed``.

    Ray's PB2 (on its PBT) picks the member to copy with ``random.choice``, starts the bandit's
    optimiser from ``np.random`` draws, and acts on results in the order they arrive. Here members
    wait for each other at every perturbation (``synch``), the bandit's data are kept in a fixed
    order, every exploit/explore step runs with both global generators seeded from this scheduler's
    own generator (and restored after), and a member keeps its index (its key stream) when it copies
    another's parameters and hyper-parameters.
    """
    from ray.tune.schedulers.pb2 import PB2  # optional and slow to import: only hpo loads it

    class SeededPB2(PB2):
        def __init__(self) -> None:
            super().__init__(synch=True, **options)
            self.seeds = np.random.default_rng(seed)

        def _save_trial_state(self, state, time, result, trial):
            score = super()._save_trial_state(state, time, result, trial)
            self.data = self.data.sort_values(["Time", "Trial"], kind="stable", ignore_index=True)
            return score

        def _checkpoint_or_exploit(self, trial, *args):
            with _global_generators_seeded(int(self.seeds.integers(2**32))):
                super()._checkpoint_or_exploit(trial, *args)

        def _get_new_config(self, trial, trial_to_clone):
            config, operations = super()._get_new_config(trial, trial_to_clone)
            return {**config, "member": trial.config["member"]}, operations

    return SeededPB2()


def _suffix(run: int) -> str:
    """What names the ``run``-th PB2 run's members and files: nothing for the first."""
    return f"-s{run}" if run else ""


def _tune(spec: HPOSpec, run: int, path: Path, address: str | None, progress: bool, verbose: bool):
    """Run PB2 from base seed ``spec.seed + run``; return the schedule (one row per member and
    round) and the best member's result.

    Ray's and Tune's own output goes to ``ray/ray.log`` in the run; ``verbose`` shows it (and Tune's
    status tables) on the terminal instead."""
    # Ray is optional and slow to import: only the hpo protocol loads it.
    import ray
    from ray import tune
    from ray.tune.search.basic_variant import BasicVariantGenerator

    bounds = spec.bounds()
    schedule_rows: list[dict] = []

    class Schedule(tune.Callback):
        """Each member's return and hyper-parameters at every round, as the driver receives them."""

        def on_trial_result(self, iteration, trials, trial, result, **info):
            member = trial.config["member"]
            schedule_rows.append(
                {
                    "trial": f"member-{member}{_suffix(run)}",
                    "kind": "pb2",
                    "variant": spec.variants[0],
                    "seed": run,
                    "member": member,
                    "step": int(result["env_steps"]),
                    "episode_return": float(result["return"]),
                    **{f"hp.{name}": float(result[f"hp/{name}"]) for name in bounds},
                }
            )
            if progress:
                print(
                    f"hpo: {f'run {run + 1}/{spec.seeds}, ' if spec.seeds > 1 else ''}member "
                    f"{member}, round {result['training_iteration']}/{spec.rounds}: "
                    f"return {float(result['return']):.4g}",
                    file=sys.stderr,
                    flush=True,
                )

    scheduler = seeded_pb2(
        spec.seed + run,
        time_attr="training_iteration",
        perturbation_interval=1,
        hyperparam_bounds={name: list(ends) for name, ends in bounds.items()},
        quantile_fraction=0.5 if spec.population < 4 else 0.25,
        log_config=False,
    )
    log = path / "ray" / "ray.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "a") as stream, contextlib.nullcontext() if verbose else ray_output_to(stream):
        if not ray.is_initialized():
            start_ray(address)
        tuner = tune.Tuner(
            tune.with_resources(_trainable, {"cpu": 1}),
            param_space={
                "spec": spec_to_dict(spec),
                "run": run,
                "member": tune.grid_search(list(range(spec.population))),
                **{name: tune.uniform(low, high) for name, (low, high) in bounds.items()},
            },
            tune_config=tune.TuneConfig(
                scheduler=scheduler,
                search_alg=BasicVariantGenerator(random_state=spec.seed + run),
                metric="return",
                mode="max",
                num_samples=1,  # the grid over members makes the population
                reuse_actors=True,  # a member restarted each round keeps its process
            ),
            run_config=tune.RunConfig(
                name=f"pb2{_suffix(run)}",
                storage_path=str((path / "ray").resolve()),
                stop={"training_iteration": spec.rounds},
                verbose=1 if verbose else 0,  # else the Schedule callback prints a line per round
                callbacks=[Schedule()],
            ),
        )
        grid = tuner.fit()
    errors = [str(error) for error in grid.errors]
    if errors:
        raise RuntimeError(f"PB2 members failed: {errors[0]}")
    schedule = pd.DataFrame(schedule_rows).sort_values(["member", "step"], ignore_index=True)
    best = grid.get_best_result(metric="return", mode="max", scope="last")
    with best.checkpoint.as_directory() as folder:
        params = load_checkpoint(Path(folder) / "params.npz")
    return schedule, {"config": best.config, "params": params}


def _evaluate_best(spec: HPOSpec, plan, run: int, best: dict) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The ``run``-th search's best member on the test contexts, and on its training contexts next
    to a random policy."""
    env = spec.make_env()
    train, test = plan.sets["train"].contexts, plan.sets["test"].contexts
    hyper = {name: best["config"][name] for name in spec.bounds()}
    config = spec._config(hyper)
    returns_of = _evaluator(spec, env, config, train)
    random_returns_of = _evaluator(spec, env, None, train, agent="random")
    key = jax.random.fold_in(jax.random.key(spec.seed + run), TEST_KEY)
    returns = returns_of(best["params"], test, key)
    own = jax.tree_util.tree_map(lambda leaf: leaf[:16], train)
    trained = float(returns_of(best["params"], own, key).mean())
    random = float(random_returns_of(None, own, key).mean())
    space = env.context_space
    evaluations = pd.DataFrame(
        {
            "trial": f"best{_suffix(run)}",
            "kind": "best",
            "variant": spec.variants[0],
            "seed": run,
            "test_set": "test",
            "context_index": np.arange(len(returns)),
            **{f"ctx.{n}": np.asarray(getattr(test, n)) for n in space.names},
            **{f"hp.{name}": float(value) for name, value in hyper.items()},
            "return": returns.astype(np.float64),
        }
    )
    training = pd.DataFrame(
        {
            "trial": [f"best{_suffix(run)}"],
            "kind": ["best"],
            "variant": [spec.variants[0]],
            "seed": [run],
            "train_return": [trained],
            "random_return": [random],
        }
    )
    return training, evaluations


def _sections(spec: HPOSpec, plan, cells: pd.DataFrame, curves: pd.DataFrame) -> list[Section]:
    bounds = spec.bounds()
    found = cells.dropna(subset=["return"]).groupby("seed").first()  # per PB2 run, its best
    several = spec.seeds > 1
    rows = [
        {
            **({"PB2 run": int(run)} if several else {}),
            "hyper-parameter": name,
            "best": float(row[f"hp.{name}"]),
            "low": low,
            "high": high,
        }
        for run, row in found.iterrows()
        for name, (low, high) in bounds.items()
    ]
    (scores,) = score_matrices(cells).values()  # the best members: a seed per PB2 run × contexts
    means = np.ma.compressed(metrics.context_means(scores.matrix))
    searches = (
        f"{spec.seeds} PB2 runs on the same contexts, from base seeds {spec.seed} to "
        f"{spec.seed + spec.seeds - 1}; in each, "
        if several
        else ""
    )
    later = f" (later runs': best-s1.yaml to best-s{spec.seeds - 1}.yaml)" if several else ""
    per_run = cells.groupby("seed")["return"].mean()
    text = [
        f"PB2 on Ray Tune: {searches}{spec.population} {spec.agent} agents ({spec.variants[0]}) "
        f"trained on {spec.num_train_contexts} contexts for {spec.rounds} rounds of "
        f"{spec.steps_per_round} steps; after each round the worst members take the parameters of "
        "the best and new hyper-parameters from PB2's bandit. The best member's final "
        f"configuration is in {BEST_FILE}{later} (use it with: contextrl run PROTOCOL "
        f"--agent-config {BEST_FILE}).",
        f"Best member{'s' if several else ''} on {len(means)} test contexts "
        f"({spec.eval_episodes} episodes each): mean return "
        f"{metrics.aggregate_mean(scores.matrix):.4g}, worst context {means.min():.4g}, best "
        f"{means.max():.4g}"
        + ("; per PB2 run: " + ", ".join(f"{value:.4g}" for value in per_run) if several else "")
        + ".",
    ]
    figures = []
    if not curves.empty:
        schedules = {
            name: {
                trial: (group["step"].to_numpy(), group[f"hp.{name}"].to_numpy())
                for trial, group in curves.groupby("trial")
            }
            for name in bounds
        }
        schedules["return"] = {
            trial: (group["step"].to_numpy(), group["episode_return"].to_numpy())
            for trial, group in curves.groupby("trial")
        }
        figures.append(
            figure(
                "hpo-schedules",
                plots.schedules(schedules, xlabel="environment steps"),
                "Each member's hyper-parameters and training-context return over training",
            )
        )
    figures.append(
        figure(
            "hpo-test-ecdf",
            plots.ecdf({"best configuration": scores.values}, title="Test returns"),
            "eCDF of the best member's returns on the test contexts",
        )
    )
    return [
        Section("Hyper-parameter optimisation (PB2)", text, [("Best configuration", rows)], figures)
    ]


def _expand(spec: HPOSpec) -> tuple[dict, list]:
    """The training and test sets, and a trial per PB2 run: its best member (the members
    themselves are Ray Tune's trials, run by _execute)."""
    return train_and_test_sets(spec), _trials(spec)


def _outline(spec: HPOSpec) -> tuple[dict, list]:
    return train_and_test_sizes(spec), _trials(spec)


def _trials(spec: HPOSpec) -> list[Trial]:
    return [
        Trial(f"best{_suffix(run)}", "best", spec.variants[0], run, "train", "test")
        for run in range(spec.seeds)
    ]


def _execute(spec: HPOSpec, run, plan, *, executor, address, max_chunks, progress, verbose):
    """Run each unfinished PB2 search on Ray (here, or on the cluster at ``address``), one chunk
    each: its schedule, best configuration and best member's test returns."""
    start = time.perf_counter()
    earlier = run.manifest().get("wall_seconds", 0.0)  # spent by earlier invocations
    skipped = sorted(run.finished())
    todo = [k for k in range(len(plan.chunks)) if k not in skipped][:max_chunks]
    for k in todo:
        search_start = time.perf_counter()
        schedule, best = _tune(spec, k, run.path, address, progress, verbose)
        training, evaluations = _evaluate_best(spec, plan, k, best)
        hyper = {name: float(best["config"][name]) for name in spec.bounds()}
        best_file = run.path / f"best{_suffix(k)}.yaml"
        write_text(best_file, yaml.safe_dump({**spec.agent_options, **hyper}, sort_keys=True))
        write_parquet(run.path / "curves" / f"chunk-{k:04d}.parquet", schedule)
        write_parquet(run.path / "training" / f"chunk-{k:04d}.parquet", training)
        run.record_timing(k, time.perf_counter() - search_start)
        write_parquet(run.result_path(k), evaluations)
        run.update_manifest(wall_seconds=earlier + time.perf_counter() - start)
        if progress:
            print(f"best configuration: {best_file}", flush=True)
    remaining = sorted(set(range(len(plan.chunks))) - run.finished())
    return Summary(todo, skipped, [], remaining, time.perf_counter() - start)


def _runs_text(spec: HPOSpec) -> str:
    population = (
        f"a population of {spec.population} members, {spec.rounds} rounds of "
        f"{spec.steps_per_round} steps each"
    )
    if spec.seeds > 1:
        return (
            f"{spec.seeds} PB2 runs (base seeds {spec.seed} to {spec.seed + spec.seeds - 1}), each "
            f"{population}; each run's best member is evaluated"
        )
    return f"{population} (base seed {spec.seed}); the best member is evaluated"


def _progress_row(spec: HPOSpec, run, plan, results, failures) -> dict:
    return {
        "PB2 runs": len(plan.chunks),
        "runs finished": len(run.finished()),
        "population": spec.population,
        "rounds": spec.rounds,
        "seconds": round(sum(run.timings().values()), 1),
    }


register_protocol(
    Protocol(
        HPOSpec,
        _sections,
        _expand,
        _outline,
        execute=_execute,
        runs_on_ray=True,
        training_section=False,  # its sections draw each member's schedule and return instead
        runs_text=_runs_text,
        progress_row=_progress_row,
    )
)
