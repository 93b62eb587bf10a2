"""Experiment specs: one typed, frozen dataclass per protocol, parsed from YAML/dicts and validated.

Every check runs before anything is trained: an unknown environment, feature, agent, visibility
variant or key, an empty distribution, an empty or overlapping train/test split all raise
:class:`SpecError` naming the field, the value and the valid choices.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Mapping
from typing import Any

from contextrl.context.distributions import (
    Categorical,
    Constant,
    LogUniform,
    Normal,
    RelativeUniform,
    Scaled,
    Uniform,
    check_spec,
)
from contextrl.context.features import ContextError

PROTOCOLS = ("sensitivity", "optimality_gap", "visibility", "train_test", "tabular")
AGENTS = ("ppo", "dqn", "c51", "random")
VARIANTS = ("hidden", "concat_all", "concat_varying", "gated")
DISTRIBUTION_NAMES = {
    "uniform": Uniform,
    "log_uniform": LogUniform,
    "normal": Normal,
    "categorical": Categorical,
    "constant": Constant,
    "scaled": Scaled,
    "relative_uniform": RelativeUniform,
}


class SpecError(ValueError):
    """An invalid experiment spec; raised before anything runs."""


def parse_distribution(feature: str, value: Any):
    """``{"uniform": [0.25, 0.75]}``, ``"uniform:0.25:0.75"``, a distribution object or a number."""
    if isinstance(value, tuple(DISTRIBUTION_NAMES.values())):
        return value
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
            return Categorical(tuple(args))
        args = args if isinstance(args, (list, tuple)) else [args]
        try:
            return DISTRIBUTION_NAMES[name](*args)
        except TypeError as error:
            raise SpecError(f"{feature}: bad arguments {args!r} for {name} ({error})") from None
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise SpecError(f"{feature}: cannot read {value!r} as a distribution or a value")
    return Constant(value)


def distribution_to_yaml(distribution) -> Any:
    """The inverse of :func:`parse_distribution`, for writing the resolved spec."""
    for name, cls in DISTRIBUTION_NAMES.items():
        if type(distribution) is cls:
            values = [v for v in dataclasses.astuple(distribution) if v is not None]
            if name == "categorical":
                return {name: list(distribution.choices)}
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
    batch_size: int = 16  # trials trained together in one vmapped call (one chunk)
    bootstrap_reps: int = 2000

    def validate(self) -> None:
        _check_int("seeds", self.seeds, 1)
        _check_int("seed", self.seed, 0)
        _check_int("eval_episodes", self.eval_episodes, 1)
        _check_int("batch_size", self.batch_size, 1)
        _check_int("bootstrap_reps", self.bootstrap_reps, 1)
        if self.max_steps is not None:
            _check_int("max_steps", self.max_steps, 1)
        if self.protocol == "tabular":
            return
        if self.agent not in AGENTS:
            raise SpecError(f"agent: unknown agent {self.agent!r}; choose one of {list(AGENTS)}")
        if not isinstance(self.agent_options, Mapping):
            raise SpecError(f"agent_options must be a mapping, got {self.agent_options!r}")
        if not self.variants:
            raise SpecError(f"variants: give at least one of {list(VARIANTS)}")
        for variant in self.variants:
            if variant not in VARIANTS:
                raise SpecError(
                    f"variants: unknown variant {variant!r}; choose from {list(VARIANTS)}"
                )
        if len(set(self.variants)) != len(self.variants):
            raise SpecError(f"variants: {list(self.variants)} repeats a variant")
        self.make_env()

    def make_env(self):
        """The environment (hidden observation; agents add their own context input)."""
        import contextrl as crl

        try:
            registered = crl.spec(self.env)
        except KeyError as error:
            raise SpecError(f"env: {error.args[0]}") from None
        if registered.host:
            jax_envs = [i for i in crl.registered() if not crl.spec(i).host]
            raise SpecError(
                f"env: {self.env} is a host environment (stepped outside JAX); the agents here train "
                f"JAX environments: choose one of {jax_envs}"
            )
        kwargs = {} if self.max_steps is None else {"max_steps": self.max_steps}
        return crl.make(self.env, **kwargs)

    def space(self):
        return self.make_env().context_space

    def resolve_features(self, field: str, features: Mapping[str, Any]) -> dict:
        """Distributions checked against the env's features (names or paper aliases)."""
        if not isinstance(features, Mapping) or not features:
            raise SpecError(f"{field}: give at least one feature distribution, got {features!r}")
        parsed = {name: parse_distribution(name, value) for name, value in features.items()}
        try:
            return check_spec(self.space(), parsed)
        except ContextError as error:
            raise SpecError(f"{field}: {error}") from None


@dataclasses.dataclass(frozen=True)
class SensitivitySpec(CommonSpec):
    """Train on the default context; evaluate with each feature scaled by A × default (paper §6.1)."""

    features: tuple[str, ...] | str = "all"  # "all": every numeric feature with a non-zero default
    magnitudes: tuple[float, ...] = tuple(round(0.1 * i, 1) for i in range(1, 23))

    def validate(self) -> None:
        super().validate()
        if not self.magnitudes:
            raise SpecError("magnitudes: give at least one magnitude A")
        for magnitude in self.magnitudes:
            _check_number("magnitudes", magnitude, 0.0)
        self.feature_names()

    def feature_names(self) -> tuple[str, ...]:
        space = self.space()
        if self.features == "all":
            names = tuple(
                n for n, f in space.features.items() if f.kind != "categorical" and f.default != 0
            )
        else:
            try:
                names = tuple(space.resolve(n) for n in _as_tuple(self.features))
            except ContextError as error:
                raise SpecError(f"features: {error}") from None
            for name in names:
                f = space.features[name]
                if f.kind == "categorical" or f.default == 0:
                    raise SpecError(f"features: {name} cannot be scaled (categorical or default 0)")
        if not names:
            raise SpecError("features: no feature to vary")
        return names


@dataclasses.dataclass(frozen=True)
class OptimalityGapSpec(CommonSpec):
    """One general agent on N sampled contexts vs one specialist per context (paper §6.2)."""

    train: dict = dataclasses.field(default_factory=lambda: {"length": {"uniform": [0.25, 0.75]}})
    num_contexts: int = 64

    def validate(self) -> None:
        super().validate()
        _check_int("num_contexts", self.num_contexts, 1)
        self.resolve_features("train", self.train)


@dataclasses.dataclass(frozen=True)
class VisibilitySpec(CommonSpec):
    """Hidden vs visible context: training curves and returns on held-out contexts (paper §6.3)."""

    variants: tuple[str, ...] = ("hidden", "concat_all", "concat_varying")
    train: dict = dataclasses.field(default_factory=lambda: {"length": {"uniform": [0.25, 0.75]}})
    test: dict | None = None  # None: held-out contexts from the training distribution
    num_train_contexts: int = 64
    num_test_contexts: int = 64

    def validate(self) -> None:
        super().validate()
        _check_int("num_train_contexts", self.num_train_contexts, 1)
        _check_int("num_test_contexts", self.num_test_contexts, 1)
        self.resolve_features("train", self.train)
        if self.test is not None:
            self.resolve_features("test", self.test)


@dataclasses.dataclass(frozen=True)
class TrainTestSpec(CommonSpec):
    """Kirk et al.'s modes over two features (paper §6.4).

    ``train_box``/``test_box`` map each of the two features to [low, high]. Mode A trains on the whole
    train box, B on an L-shaped band of width ``band`` (a fraction of each range) along the low edges,
    C on the two low edges themselves (single values per feature). Test contexts cover the test box,
    which must reach beyond the train box on both features so every region is tested.
    """

    variants: tuple[str, ...] = ("hidden", "concat_varying")
    modes: tuple[str, ...] = ("A", "B", "C")
    train_box: dict = dataclasses.field(
        default_factory=lambda: {"length": [0.25, 0.75], "tau": [0.015, 0.025]}
    )
    test_box: dict = dataclasses.field(
        default_factory=lambda: {"length": [0.05, 1.5], "tau": [0.005, 0.05]}
    )
    band: float = 0.1
    num_train_contexts: int = 64
    num_test_contexts: int = 144

    def validate(self) -> None:
        super().validate()
        for mode in self.modes:
            if mode not in ("A", "B", "C"):
                raise SpecError(f"modes: unknown mode {mode!r}; choose from ['A', 'B', 'C']")
        if not self.modes:
            raise SpecError("modes: give at least one of ['A', 'B', 'C']")
        _check_int("num_train_contexts", self.num_train_contexts, 1)
        _check_int("num_test_contexts", self.num_test_contexts, 4)
        _check_number("band", self.band, 0.0)
        if not self.band < 1.0:
            raise SpecError(f"band: must be below 1 (a fraction of the range), got {self.band!r}")
        train, test = self.boxes()
        for name in train:
            (tl, th), (sl, sh) = train[name], test[name]
            if not (sl < tl and th < sh):
                raise SpecError(
                    f"test_box/train_box: test range {[sl, sh]} of {name} overlaps the train range "
                    f"{[tl, th]} without reaching beyond it on both sides; the protocol needs "
                    "extrapolation regions"
                )

    def boxes(self) -> tuple[dict, dict]:
        """Canonical feature names → (low, high), checked against the feature bounds."""
        space = self.space()
        out = []
        for field, box in (("train_box", self.train_box), ("test_box", self.test_box)):
            if not isinstance(box, Mapping) or len(box) != 2:
                raise SpecError(f"{field}: give exactly two features with [low, high], got {box!r}")
            resolved = {}
            for name, ends in box.items():
                try:
                    canonical = space.resolve(name)
                except ContextError as error:
                    raise SpecError(f"{field}: {error}") from None
                if not isinstance(ends, (list, tuple)) or len(ends) != 2:
                    raise SpecError(f"{field}.{name}: give [low, high], got {ends!r}")
                low, high = (_check_number(f"{field}.{name}", v) for v in ends)
                if not low < high:
                    raise SpecError(f"{field}.{name}: empty range [{low}, {high}]")
                try:
                    Uniform(low, high).check(space.features[canonical])
                except ContextError as error:
                    raise SpecError(f"{field}: {error}") from None
                resolved[canonical] = (low, high)
            out.append(resolved)
        if list(out[0]) != list(out[1]):
            raise SpecError(
                f"train_box and test_box must name the same two features in the same order, "
                f"got {list(out[0])} and {list(out[1])}"
            )
        return out[0], out[1]


@dataclasses.dataclass(frozen=True)
class TabularSpec(CommonSpec):
    """Exact optimality gaps on the paper's 3-state cMDP and seeded random tabular cMDPs."""

    env: str = "tabular"
    agent: str = "value_iteration"
    num_random: int = 8
    states: int = 4
    actions: int = 2
    contexts: int = 3
    discount: float = 0.9

    def validate(self) -> None:
        super().validate()
        for field in ("num_random", "states", "actions", "contexts"):
            _check_int(field, getattr(self, field), 1 if field != "num_random" else 0)
        if self.actions**self.states > 100_000:
            raise SpecError(
                f"states/actions: {self.actions}^{self.states} deterministic policies are too many "
                "to enumerate exactly (limit 100000)"
            )
        _check_number("discount", self.discount, 0.0)
        if not self.discount < 1.0:
            raise SpecError(f"discount: must be below 1, got {self.discount!r}")


SPECS: dict[str, type[CommonSpec]] = {
    "sensitivity": SensitivitySpec,
    "optimality_gap": OptimalityGapSpec,
    "visibility": VisibilitySpec,
    "train_test": TrainTestSpec,
    "tabular": TabularSpec,
}


def _check_int(field: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise SpecError(f"{field}: expected an integer >= {minimum}, got {value!r}")
    return value


def _check_number(field: str, value: Any, minimum: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SpecError(f"{field}: expected a finite number, got {value!r}")
    if minimum is not None and value <= minimum:
        raise SpecError(f"{field}: expected a number > {minimum}, got {value!r}")
    return float(value)


def _as_tuple(value: Any) -> tuple:
    return (value,) if isinstance(value, str) else tuple(value)


def parse_spec(data: Mapping[str, Any]) -> CommonSpec:
    """A validated spec from a mapping (a YAML file's content, CLI options)."""
    if not isinstance(data, Mapping):
        raise SpecError(f"a spec is a mapping of fields, got {type(data).__name__}")
    protocol = data.get("protocol")
    if protocol not in SPECS:
        raise SpecError(f"protocol: unknown protocol {protocol!r}; choose one of {list(PROTOCOLS)}")
    cls = SPECS[protocol]
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise SpecError(
            f"unknown field(s) {unknown} for protocol {protocol}; valid: {sorted(fields)}"
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
    spec = cls(**values)
    spec.validate()
    return spec


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
