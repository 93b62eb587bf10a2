"""Experiment specs: one typed, frozen dataclass per protocol, parsed from YAML/dicts and validated.

A protocol *is* its spec class: each protocol module (sensitivity, optimality_gap, visibility,
train_test, tabular, hpo) subclasses :class:`CommonSpec`, registers it with :func:`register_protocol`
and implements how it expands into trials, how it runs (chunks of trials by default) and which report
sections it contributes; nothing else in the package names a protocol.

Every check runs before anything is trained: an unknown environment, feature, agent, visibility
variant or key, an empty distribution, an empty or overlapping train/test split all raise
:class:`SpecError` naming the field, the value and the valid choices.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import math
import re
import typing
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import yaml

import contextrl as crl
from contextrl.agents import VARIANTS, ConfigError, get_agent
from contextrl.analysis.intervals import SAMPLED
from contextrl.context import distributions
from contextrl.context.features import ContextError

DISTRIBUTION_NAMES = {
    "uniform": distributions.Uniform,
    "log_uniform": distributions.LogUniform,
    "normal": distributions.Normal,
    "categorical": distributions.Categorical,
    "constant": distributions.Constant,
    "scaled": distributions.Scaled,
    "relative_uniform": distributions.RelativeUniform,
}


class SpecError(ValueError):
    """An invalid experiment spec; raised before anything runs."""


# What each protocol varies on an environment when neither --vary nor a config says: a training
# distribution (``train``), Kirk et al.'s two-feature boxes (``train_box``/``test_box``), or the
# curriculum protocol's whole ranges and ADR's return thresholds (``ranges``, ``adr_thresholds``).
# Protocols name the fields they take from here (``CommonSpec.env_defaults``); an environment
# missing here needs --vary, so a default never names another environment's feature.
ENV_DEFAULTS: dict[str, dict[str, dict]] = {
    "CartPole": {
        "train": {"length": {"uniform": [0.25, 0.75]}},
        "train_box": {"length": [0.25, 0.75], "tau": [0.015, 0.025]},
        "test_box": {"length": [0.05, 1.5], "tau": [0.005, 0.05]},
        "ranges": {"length": [0.05, 5.0]},
        "adr_thresholds": [100.0, 400.0],
    },
    "Pendulum": {
        "train": {"l": {"uniform": [0.5, 1.5]}},
        "train_box": {"l": [0.75, 1.25], "m": [0.75, 1.25]},
        "test_box": {"l": [0.25, 2.0], "m": [0.25, 2.0]},
        "ranges": {"g": [2.0, 20.0], "l": [0.25, 2.5]},
        "adr_thresholds": [-1000.0, -400.0],
    },
    "MountainCar": {
        "train": {"gravity": {"uniform": [0.002, 0.003]}},
        "train_box": {"gravity": [0.002, 0.003], "force": [0.0008, 0.0012]},
        "test_box": {"gravity": [0.001, 0.005], "force": [0.0004, 0.002]},
    },
    "MountainCarContinuous": {
        "train": {"gravity": {"uniform": [0.002, 0.003]}},
        "train_box": {"gravity": [0.002, 0.003], "power": [0.0012, 0.0018]},
        "test_box": {"gravity": [0.001, 0.005], "power": [0.0006, 0.003]},
    },
    "Acrobot": {
        "train": {"LINK_LENGTH_1": {"uniform": [0.75, 1.25]}},
        "train_box": {"LINK_LENGTH_1": [0.75, 1.25], "LINK_MASS_1": [0.75, 1.25]},
        "test_box": {"LINK_LENGTH_1": [0.25, 2.0], "LINK_MASS_1": [0.25, 2.0]},
    },
}


class _SpecLoader(yaml.SafeLoader):
    """PyYAML's safe loader reading exponents as numbers, as YAML 1.2 does (YAML 1.1, PyYAML's
    default, wants ``1.0e+5`` and reads ``1e5`` as a string). A whole number written with an exponent
    and no point (``1e5``) is an int, so it can be a step count; ``2.5e-3`` is a float."""


_EXPONENT_TAG = "tag:contextrl,2024:exponent"
_SpecLoader.add_implicit_resolver(
    _EXPONENT_TAG,
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)?(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


def _exponent(loader: yaml.SafeLoader, node: yaml.ScalarNode) -> int | float:
    text = loader.construct_scalar(node).replace("_", "")
    value = float(text)
    return int(value) if "." not in text and value.is_integer() else value


_SpecLoader.add_constructor(_EXPONENT_TAG, _exponent)


def load_yaml(text: str, source: str = "YAML") -> Any:
    """YAML text as data; a syntax error becomes a one-line :class:`SpecError` with line and column."""
    try:
        return yaml.load(text, Loader=_SpecLoader)  # noqa: S506  (a SafeLoader subclass)
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise SpecError(f"{source}: YAML syntax error{where}: {error.problem}") from None
    except yaml.YAMLError as error:
        raise SpecError(f"{source}: cannot read YAML ({error})") from None


def parse_assignments(
    items: list[str],
    option: str,
    form: str = "NAME=VALUE",
    read: Callable[[str, str], Any] | None = None,
) -> dict[str, Any]:
    """Command-line ``NAME=VALUE`` items as ``{name: read(name, value)}`` (by default the value read
    as YAML): the one reader of ``--set``, ``--agent-option``, ``--vary`` and ``--test``. An item
    without ``=``, a name or a value is refused in one line naming the option and the ``form``; so is a
    name given twice (which value was meant is not for the command to guess)."""
    out, given = {}, {}
    for item in items:
        name, sep, value = (part.strip() for part in item.partition("="))
        if not sep or not name or not value:
            raise SpecError(f"{option}: expected {form}, got {item!r}")
        if name in given:
            raise SpecError(
                f"{option}: {name} is given twice ({given[name]}, {value}); give it once"
            )
        given[name] = value
        out[name] = load_yaml(value, f"{option} {name}") if read is None else read(name, value)
    return out


_HOST_ENVS: dict[tuple[str, str | None], Any] = {}


def parse_distribution(feature: str, value: Any):
    """``{"uniform": [0.25, 0.75]}``, ``"uniform:0.25:0.75"``, a distribution object or a number."""
    if isinstance(value, tuple(DISTRIBUTION_NAMES.values())):
        return value
    if isinstance(value, str) and value.strip().startswith(("{", "[")):  # YAML on the command line
        value = load_yaml(value, feature)
    if isinstance(value, str) and ":" in value:
        name, *args = value.split(":")
        try:
            value = {name: [a if name == "categorical" else float(a) for a in args]}
        except ValueError as error:
            raise SpecError(f"{feature}: cannot read distribution {value!r} ({error})") from None
    if isinstance(value, Mapping):
        if len(value) != 1:
            raise SpecError(
                f"{feature}: a distribution is one mapping {{name: [args]}}, got {value!r}"
            )
        ((name, args),) = value.items()
        if name not in DISTRIBUTION_NAMES:
            raise SpecError(
                f"{feature}: unknown distribution {name!r}; choose one of {list(DISTRIBUTION_NAMES)}"
            )
        if name == "categorical":
            return _categorical(feature, args)
        args = args if isinstance(args, (list, tuple)) else [args]
        try:
            return DISTRIBUTION_NAMES[name](*args)
        except TypeError:
            fields = dataclasses.fields(DISTRIBUTION_NAMES[name])
            names = [f.name for f in fields if f.default is dataclasses.MISSING]
            optional = [f.name for f in fields if f.default is not dataclasses.MISSING]
            takes = f"[{', '.join(names)}]" + (
                f" (optional: {', '.join(optional)})" if optional else ""
            )
            raise SpecError(
                f"{feature}: {name} takes {takes}, got {list(args)!r}; e.g. {feature}: "
                f"{{{name}: [{', '.join(names)}]}} in YAML or {feature}={name}:"
                f"{':'.join(names)} with --vary"
            ) from None
    if isinstance(value, str):  # "0.5" from the command line is the number YAML reads
        loaded = load_yaml(value, feature)
        value = (
            loaded if isinstance(loaded, (int, float)) and not isinstance(loaded, bool) else value
        )
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise SpecError(f"{feature}: cannot read {value!r} as a distribution or a value")
    return distributions.Constant(value)


def _categorical(feature: str, args: Any) -> distributions.Categorical:
    """``[a, b]`` (equal weights), ``{choices: [a, b], weights: [1, 3]}`` or ``{a: 1, b: 3}``."""
    if isinstance(args, Mapping):
        if set(args) <= {"choices", "weights"} and "choices" in args:
            choices, weights = args["choices"], args.get("weights")
        else:
            choices, weights = list(args), list(args.values())
        if not isinstance(choices, (list, tuple)) or (
            weights is not None and not isinstance(weights, (list, tuple))
        ):
            raise SpecError(
                f"{feature}: categorical takes {{choices: [...], weights: [...]}}, got {args!r}"
            )
        if weights is not None and len(weights) != len(choices):
            raise SpecError(
                f"{feature}: categorical has {len(choices)} choices but {len(weights)} weights"
            )
        return distributions.Categorical(
            tuple(choices), None if weights is None else tuple(weights)
        )
    return distributions.Categorical(tuple(args if isinstance(args, (list, tuple)) else [args]))


def distribution_to_yaml(distribution) -> Any:
    """The inverse of :func:`parse_distribution`, for writing the resolved spec."""
    for name, cls in DISTRIBUTION_NAMES.items():
        if type(distribution) is cls:
            values = [v for v in dataclasses.astuple(distribution) if v is not None]
            if name == "categorical":
                if distribution.weights is None:
                    return {name: list(distribution.choices)}
                weights = [float(w) for w in distribution.weights]
                return {name: {"choices": list(distribution.choices), "weights": weights}}
            return {name: [v if isinstance(v, str) else float(v) for v in values]}
    raise SpecError(f"not a distribution: {distribution!r}")


@dataclasses.dataclass(frozen=True)
class CommonSpec:
    """Fields every protocol shares. ``seeds`` independent runs per agent variant."""

    protocol: str
    env: str = "CartPole"
    name: str = ""
    agent: str = "ppo"
    agent_options: dict = dataclasses.field(default_factory=dict)  # e.g. total_timesteps, num_envs
    variants: tuple[str, ...] = ("hidden",)  # how the agent sees the context
    seeds: int = 3
    seed: int = 0  # base seed: contexts, training keys and bootstrap all derive from it
    eval_episodes: int = 10
    max_steps: int | None = None  # episode time limit (None: the environment's)
    # the environment's simulator backend (None: its default), e.g. "mjx" for dm_control on MJX
    backend: str | None = None
    batch_size: int = 16  # trials trained together in one vmapped call (one chunk)
    bootstrap_reps: int = 2000

    trains_agents: ClassVar[bool] = True  # False: the protocol has no agent, env or variants
    vary_field: ClassVar[str | None] = "train"  # the field `contextrl run --vary` sets
    env_defaults: ClassVar[tuple[str, ...]] = ()  # fields (None) filled from ENV_DEFAULTS
    # The test contexts' part in the intervals: drawn from the distribution a claim is about
    # (resampled with the seeds), or a fixed grid or sweep the claim is about (seeds only).
    test_contexts: ClassVar[str] = SAMPLED
    # Shared fields the protocol does not use, each with why: set off its default, one is refused.
    unused_fields: ClassVar[dict[str, str]] = {}

    @property
    def design(self) -> dict[str, Any]:
        """How the report's intervals resample (the keywords of the statistics in
        :mod:`contextrl.analysis.scores`): the test contexts' part, replicates, and the seed."""
        return {"contexts": self.test_contexts, "reps": self.bootstrap_reps, "seed": self.seed}

    def validate(self) -> None:
        check_int("seeds", self.seeds, 1)
        check_int("seed", self.seed, 0, 2**32 - 1)
        check_int("eval_episodes", self.eval_episodes, 1)
        check_int("batch_size", self.batch_size, 1)
        check_int("bootstrap_reps", self.bootstrap_reps, 1)
        if self.max_steps is not None:
            check_int("max_steps", self.max_steps, 1, MAX_INT32)
        if self.backend is not None and not isinstance(self.backend, str):
            raise SpecError(f"backend: expected a backend name, got {self.backend!r}")
        self._refuse_unused(self.unused_fields)
        if not self.trains_agents:
            return
        if not isinstance(self.agent_options, Mapping):
            raise SpecError(agent_options_error(self.agent_options))
        if not self.variants:
            raise SpecError(f"variants: give at least one of {list(VARIANTS)}")
        for variant in self.variants:
            if variant not in VARIANTS:
                raise SpecError(
                    f"variants: unknown variant {variant!r}; choose from {list(VARIANTS)}"
                )
        if len(set(self.variants)) != len(self.variants):
            raise SpecError(f"variants: {list(self.variants)} repeats a variant")
        env = self.make_env()
        agent = self.agent_entry()
        try:
            agent.check_action_space(env, host=self.host)
            for variant in self.variants:
                agent.config(self.env, self.agent_options, variant)
        except ConfigError as error:
            raise SpecError(f"agent_options: {error}") from None
        for field in self.env_defaults:
            if getattr(self, field) is None:  # parse_spec found no default for this environment
                env_id = crl.spec(self.env).id
                raise SpecError(
                    f"{field}: the {self.protocol} protocol needs --vary for {env_id} (it has no "
                    f"default {field} there); e.g. {_vary_example(type(self), env_id)}"
                )

    def _refuse_unused(self, reasons: Mapping[str, str]) -> None:
        """Refuse each named field set off its default: the protocol would ignore it silently."""
        fields = {f.name: f for f in dataclasses.fields(self)}
        for name, why in reasons.items():
            field = fields[name]
            default = field.default_factory() if callable(field.default_factory) else field.default
            value = getattr(self, name)
            if value != default and not (name == "variants" and tuple(value) == default):
                raise SpecError(
                    f"{name}: the {self.protocol} protocol {why}, so {name}={value!r} does not "
                    "apply; leave it out"
                )

    def make_curriculum(self, name: str, pool: Any):
        """The curriculum ``name`` of a trial over the contexts ``pool`` (protocols that have one)."""
        raise SpecError(f"the {self.protocol} protocol trains no agent under a curriculum ({name})")

    def gradient_features(self, env) -> tuple[str, ...]:
        """Float features of ``env`` whose return gradient each trained agent's trial also gives at
        the default context (``contextrl.core.gradient``); none by default."""
        return ()

    def agent_entry(self):
        """The registered agent of this spec."""
        try:
            return get_agent(self.agent)
        except KeyError as error:
            raise SpecError(f"agent: {error.args[0]}") from None

    def agent_config(self, variant: str):
        """The agent's config for one visibility variant (None for an untrained agent)."""
        return self.agent_entry().config(self.env, self.agent_options, variant)

    def training_steps(self, trials) -> int:
        """Environment steps the agents of ``trials`` (a plan's) train for, summed."""
        budgets = {
            variant: int(getattr(self.agent_config(variant), "trained_timesteps", 0) or 0)
            for variant in {t.variant for t in trials}
        }
        return sum(budgets[t.variant] for t in trials)

    def budget_note(self) -> str | None:
        """A note where the agents train fewer steps than ``total_timesteps`` asks (whole rollouts,
        whole logging periods), so the difference is said, not found later."""
        config = self.agent_config(self.variants[0])
        asked = getattr(config, "total_timesteps", None)
        trained = getattr(config, "trained_timesteps", asked)
        if asked is None or trained == asked:
            return None
        return (
            f"note: {self.agent} trains {trained:,} of the {asked:,} total_timesteps per agent "
            f"({config.training_unit})"
        )

    @property
    def env_options(self) -> dict[str, Any]:
        """The environment's constructor options this spec sets (its backend)."""
        return {} if self.backend is None else {"backend": self.backend}

    @property
    def host(self) -> bool:
        """Whether the environment is a host environment (trained through the host collector)."""
        try:
            return crl.spec(self.env).runs_on_host(self.env_options)
        except KeyError as error:
            raise SpecError(f"env: {error.args[0]}") from None

    def make_env(self):
        """The environment (hidden observation; agents add their own context input). A host
        environment is built once per process and shared: specs only read its spaces."""
        host = self.host  # an unknown environment is refused here, named
        try:
            crl.spec(self.env).check_backend(self.backend, "backend")
        except ValueError as error:
            raise SpecError(str(error)) from None
        try:
            if host:
                key = (self.env, self.backend)
                if key not in _HOST_ENVS:
                    _HOST_ENVS[key] = crl.make(self.env, **self.env_options)
                return _HOST_ENVS[key]
            kwargs = {} if self.max_steps is None else {"max_steps": self.max_steps}
            return crl.make(self.env, **self.env_options, **kwargs)
        except ValueError as error:
            if self.backend is None or "backend" not in str(error):
                raise
            raise SpecError(f"backend: {error}") from None

    def space(self):
        return self.make_env().context_space

    def resolve_features(self, field: str, features: Mapping[str, Any]) -> dict:
        """Distributions checked against the env's features (names or paper aliases)."""
        if not isinstance(features, Mapping) or not features:
            raise SpecError(f"{field}: give at least one feature distribution, got {features!r}")
        parsed = {name: parse_distribution(name, value) for name, value in features.items()}
        try:
            return distributions.check_spec(self.space(), parsed)
        except ContextError as error:
            raise SpecError(f"{field}: {error}") from None


def feature_ranges(space, field: str, box: Mapping[str, Any]) -> dict[str, tuple[float, float]]:
    """``{feature: [low, high]}`` as canonical names → (low, high), each a non-empty range inside
    the feature's bounds; anything else is one :class:`SpecError` naming ``field`` and the feature."""
    resolved = {}
    for name, ends in box.items():
        try:
            canonical = space.resolve(name)
        except ContextError as error:
            raise SpecError(f"{field}: {error}") from None
        if not isinstance(ends, (list, tuple)) or len(ends) != 2:
            raise SpecError(f"{field}.{name}: give [low, high], got {ends!r}")
        low, high = (check_number(f"{field}.{name}", v) for v in ends)
        if not low < high:
            raise SpecError(f"{field}.{name}: empty range [{low}, {high}]")
        try:
            distributions.Uniform(low, high).check(space.features[canonical])
        except ContextError as error:
            raise SpecError(f"{field}: {error}") from None
        resolved[canonical] = (low, high)
    return resolved


def merge_features(data: dict, field: str, given: Mapping[str, Any]) -> str | None:
    """Set ``data[field]`` to its features updated with ``given``; a notice when some were kept."""
    existing = data.get(field)
    existing = dict(existing) if isinstance(existing, Mapping) else {}
    data[field] = {**existing, **given}
    kept = [name for name in existing if name not in given]
    if not kept:
        return None
    replaced = [name for name in given if name in existing]
    return (
        f"--vary: {field} keeps {kept} from the config"
        + (f" and replaces {replaced}" if replaced else "")
        + f"; now {list(data[field])}"
    )


# Each protocol's spec class by name (:func:`contextrl.experiments.protocol.register_protocol`
# registers it with the protocol).
SPECS: dict[str, type[CommonSpec]] = {}


def agent_options_error(value: Any) -> str:
    """The message for agent_options that are not a mapping (often ``"key=value"`` text)."""
    example = "{total_timesteps: 1000}"
    if isinstance(value, str) and "=" in value:
        key, _, number = value.partition("=")
        example = f"{{{key.strip()}: {number.strip()}}}"
    return (
        f"agent_options: expected a mapping of agent options, got {value!r}; "
        f"in YAML write agent_options: {example} (or --agent-option KEY=VALUE)"
    )


# The most of anything a plan counts (seeds, contexts, episodes, replicates): a plan is expanded in
# memory, so a count beyond any real run is refused before it is, not after it fills the memory.
MAX_COUNT = 1_000_000
MAX_INT32 = 2**31 - 1  # step counters are int32 inside the compiled programs


def check_int(field: str, value: Any, minimum: int, maximum: int = MAX_COUNT) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise SpecError(f"{field}: expected an integer >= {minimum}, got {value!r}")
    if value > maximum:
        raise SpecError(f"{field}: expected an integer <= {maximum:,}, got {value:,}")
    return value


def check_number(field: str, value: Any, minimum: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SpecError(f"{field}: expected a finite number, got {value!r}")
    if minimum is not None and value <= minimum:
        raise SpecError(f"{field}: expected a number > {minimum}, got {value!r}")
    return float(value)


def names_tuple(value: Any) -> tuple:
    """A spec field that names one thing or several (``features: g`` or ``[g, l]``) as a tuple."""
    return (value,) if isinstance(value, str) else tuple(value)


def parse_spec(data: Mapping[str, Any]) -> CommonSpec:
    """A validated spec from a mapping (a YAML file's content, CLI options)."""
    if not isinstance(data, Mapping):
        raise SpecError(f"a spec is a mapping of fields, got {type(data).__name__}")
    protocol = data.get("protocol")
    if protocol not in SPECS:
        raise SpecError(f"protocol: unknown protocol {protocol!r}; choose one of {list(SPECS)}")
    cls = SPECS[protocol]
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise SpecError(
            f"unknown field(s) {unknown} for protocol {protocol}; valid: {sorted(fields)}"
        )
    for name in ("env", "agent", "name"):  # names the plan looks up or builds folders from
        value = data.get(name)
        if value is not None and not isinstance(value, str):
            raise SpecError(f"{name}: expected a name (a string), got {value!r}")
    if not re.fullmatch(r"[A-Za-z0-9._-]*", data.get("name") or ""):
        raise SpecError(
            f"name: {data['name']!r} names the run's folder; use letters, digits, '.', '_' and '-'"
        )
    hints = typing.get_type_hints(cls)
    values = {}
    for name, value in data.items():
        if value is not None and "tuple" in str(hints[name]) and isinstance(value, list):
            value = tuple(value)
        if name in ("variants", "modes", "magnitudes") and isinstance(value, (str, int, float)):
            value = (value,)  # one value where a list is expected
        values[name] = value
    if "name" not in values or not values["name"]:
        values["name"] = protocol
    if values.get("env") is not None:  # an alias or another spelling names the same environment
        with contextlib.suppress(KeyError):  # an unknown one is named by validate
            values["env"] = crl.spec(values["env"]).id
    _fill_env_defaults(cls, values)
    spec = cls(**values)
    spec.validate()
    return spec


def _fill_env_defaults(cls: type[CommonSpec], values: dict[str, Any]) -> None:
    """Set each of ``cls.env_defaults`` not given from the environment's entry in ENV_DEFAULTS;
    one the environment has none for stays None, which :meth:`CommonSpec.validate` refuses with
    an example on the environment's own features (after the checks of the env and agent)."""
    env = values.get("env", cls.__dataclass_fields__["env"].default)
    try:
        defaults = ENV_DEFAULTS.get(crl.spec(env).id, {})
    except (KeyError, TypeError):
        return  # validate names the registered environments
    for field in cls.env_defaults:
        if values.get(field) is None and field in defaults:
            values[field] = copy.deepcopy(defaults[field])


def _vary_example(cls: type[CommonSpec], env_id: str) -> str:
    """An example --vary for ``env_id``: its first two scalable features at 0.5-1.5 × their default,
    clipped to their bounds, in the syntax of the protocol's vary field, and every feature's name."""
    features = crl.spec(env_id).factory().context_space.features
    scalable = [(n, f) for n, f in features.items() if f.kind != "categorical" and f.default]
    ranges = [
        (n, *sorted((max(f.lower, 0.5 * f.default), min(f.upper, 1.5 * f.default))))
        for n, f in scalable[:2]
    ]
    if cls.vary_field == "train_box":
        items = " ".join(f"--vary {n}=[{lo:g},{hi:g}]" for n, lo, hi in ranges)
        tests = ", ".join(
            f"{n}: [{max(features[n].lower, lo / 2):g}, {min(features[n].upper, hi * 2):g}]"
            for n, lo, hi in ranges
        )
        example = f"{items} --set 'test_box={{{tests}}}'"
    else:
        n, lo, hi = ranges[0]
        example = f"--vary {n}=uniform:{lo:g}:{hi:g}"
    return f"{example} (features of {env_id}: {', '.join(features)})"


def spec_to_dict(spec: CommonSpec) -> dict[str, Any]:
    """Plain data for YAML (tuples become lists); parse_spec(spec_to_dict(s)) == s."""

    def plain(value):
        if isinstance(value, tuple):
            return [plain(v) for v in value]
        if isinstance(value, Mapping):
            return {k: plain(v) for k, v in value.items()}
        if isinstance(value, tuple(DISTRIBUTION_NAMES.values())):
            return distribution_to_yaml(value)
        return value

    return {f.name: plain(getattr(spec, f.name)) for f in dataclasses.fields(spec)}
