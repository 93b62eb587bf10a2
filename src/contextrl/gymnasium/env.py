"""The single gymnasium environment: any contextrl environment, JAX or host, with contexts.

    env = gymnasium.make("contextrl/CartPole-v0", contexts={"length": crl.Uniform(0.25, 1.0)},
                         obs_context_features="varying")

Everything a user can get wrong (unknown feature, out-of-bounds value, unknown selector or observation
mode) is checked in the constructor, before any episode runs. Same seed, same contexts and observations:
every random draw comes from the seed given to ``reset``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import gymnasium
import jax
import numpy as np

from contextrl.context.changes import Change, bind
from contextrl.context.features import ContextBase, ContextError
from contextrl.context.observation import ContextObservation
from contextrl.context.schedule import ContextSchedule, resolve_contexts
from contextrl.core.env import Env
from contextrl.core.host import HostEnv
from contextrl.core.registry import spec
from contextrl.gymnasium.backends import HostBackend, make_backend

RENDER_MODES = ("rgb_array", "human")


def build_env(
    env_id: str | Env | HostEnv, max_steps: int | None, env_kwargs: dict
) -> Env | HostEnv:
    """The contextrl environment behind an adapter: a registered id, or an env object as it is."""
    if isinstance(env_id, str):
        env_spec = spec(env_id)
        if env_spec.runs_on_host(env_kwargs):
            return env_spec.build(**env_kwargs)
        return env_spec.build(max_steps=max_steps, **env_kwargs)
    if env_kwargs:
        raise TypeError(f"unexpected arguments for an environment object: {sorted(env_kwargs)}")
    if isinstance(env_id, Env):
        return env_id if max_steps is None else dataclasses.replace(env_id, max_steps=max_steps)
    if isinstance(env_id, HostEnv):
        return env_id
    raise TypeError(f"env_id must be a registered id or a contextrl Env/HostEnv, got {env_id!r}")


def check_count(name: str, value: Any, *, optional: bool = False) -> None:
    """Refuse ``value`` unless it is a positive integer (or None where ``optional``)."""
    if optional and value is None:
        return
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        allowed = "a positive integer or None" if optional else "a positive integer"
        raise ValueError(f"{name} must be {allowed}, got {value!r}")


@dataclasses.dataclass(frozen=True)
class Setup:
    """What the single and the vector env build from their shared arguments, checked before any
    episode runs: the environment (a JAX env carrying ``obs_context``), its context schedule, the
    context observation, the time limit (a JAX env's own, resolved by the core) and the changes
    within an episode (bound by the core, or None)."""

    env: Env | HostEnv
    schedule: ContextSchedule
    obs_context: ContextObservation
    max_steps: int
    changes: Change | None = None


@dataclasses.dataclass(frozen=True)
class ContextView:
    """How a gymnasium face shows the context: its constructors' ``obs_context_*`` keywords as one value,
    checked once. ``features``: None (hidden), "all", "varying" or a list of names; ``as_dict``: the
    observation as ``{"obs": ..., "context": ...}``; ``normalize`` and ``noise`` as
    :meth:`ContextSchedule.observation` takes them."""

    features: None | str | Sequence[str] = None
    as_dict: bool = False
    normalize: bool = False
    noise: float = 0.0

    def __post_init__(self):
        if not isinstance(self.as_dict, bool):
            raise ContextError(f"obs_context_as_dict must be True or False, got {self.as_dict!r}")


def bound_changes(env: Env | HostEnv, changes: Change | None) -> Change | None:
    """``changes`` checked by the core (:func:`contextrl.context.changes.bind`: kind, features,
    parameters), and refused for a host environment: its simulator steps outside the core's step,
    the one place a context changes mid-episode."""
    if changes is None:
        return None
    bound = bind(env, changes)
    if not isinstance(env, Env):
        raise ContextError(
            f"{type(changes).__name__}: {env.name} is a host environment (its simulator steps on the "
            "CPU, outside the core's step), so its context cannot change mid-episode; changes= "
            "takes JAX environments"
        )
    return bound


def build_setup(
    env_id: str | Env | HostEnv,
    contexts: Any,
    context_selector: str | Callable | None,
    view: ContextView,
    max_steps: int | None,
    env_kwargs: dict,
    changes: Change | None = None,
) -> Setup:
    """The :class:`Setup` of a face's arguments (see :class:`ContextualGymEnv`)."""
    check_count("max_steps", max_steps, optional=True)
    inner = build_env(env_id, max_steps, env_kwargs)
    changes = bound_changes(inner, changes)
    schedule = resolve_contexts(inner.context_space, contexts, context_selector)
    obs_context = schedule.observation(view.features, view.normalize, view.noise)
    if view.as_dict and obs_context.hidden:
        raise ContextError(
            "obs_context_as_dict=True needs visible context features; set "
            'obs_context_features to "all", "varying" or a list of names'
        )
    if isinstance(inner, Env):
        inner = dataclasses.replace(inner, obs_context=obs_context)
        return Setup(inner, schedule, obs_context, inner.max_steps, changes)
    limit = inner.default_max_steps if max_steps is None else int(max_steps)
    return Setup(inner, schedule, obs_context, limit)


def observation_space(
    flat: gymnasium.spaces.Space, base: gymnasium.spaces.Space, as_dict: bool
) -> gymnasium.spaces.Space:
    """One copy's observation space: ``flat`` (the original observation, then the context), or a Dict
    of the original observation in its own space (pixels keep shape and dtype) and the context."""
    if not as_dict:
        return flat
    split = int(np.prod(base.shape))
    context = gymnasium.spaces.Box(flat.low[split:], flat.high[split:], dtype=np.float32)
    return gymnasium.spaces.Dict({"obs": base, "context": context})


def split_observation(flat: np.ndarray, space: gymnasium.spaces.Dict) -> dict[str, np.ndarray]:
    """``flat`` (one observation, or a row per copy) as the Dict of :func:`observation_space`."""
    base = space["obs"]
    split = int(np.prod(base.shape))
    obs = flat[..., :split].reshape(flat.shape[:-1] + base.shape)
    return {"obs": obs.astype(base.dtype, copy=False), "context": flat[..., split:]}


def run_key_bits(np_random: np.random.Generator) -> np.ndarray:
    """The run's JAX key (as uint32 data), drawn from the generator ``reset(seed=...)`` seeded.

    ``jax.random.key(seed_generator(seed).integers(2**32))``, with gymnasium's seeding, is the key a
    hand-written ``jax.vmap`` over ``ContextualEnv`` passes to reproduce a gymnasium run.
    """
    seed = int(np_random.integers(2**32, dtype=np.uint64))
    return np.asarray(jax.random.key_data(jax.random.key(seed)), np.uint32)


def render_fps(env: Env | HostEnv) -> int:
    """Frames per second of real time: one frame per action (a host env's control step, else the
    default context's time step where there is one)."""
    control_timestep = getattr(env, "control_timestep", None)
    if control_timestep:
        return max(1, round(1.0 / control_timestep))
    default = env.default_context()
    for name in ("tau", "dt", "timestep"):
        if name in env.context_space.names:
            return max(1, round(1.0 / float(getattr(default, name))))
    return 30


class ContextualGymEnv(gymnasium.Env):
    """A gymnasium ``Env`` over a contextrl environment whose every episode takes a context.

    ``contexts``: None (the default context), one context (dict of feature values or a context object),
    a mapping id → context, a list of contexts, a batch from ``crl.sample``, or a dict of distributions
    resampled at every reset. ``context_selector``: "round_robin" (default), "random" (seeded from
    ``reset(seed=...)``), "static", or ``fn(key, episode, n) -> index``. ``obs_context_features``:
    None (the original observation), "all", "varying" or a list of names, appended to the observation, or
    given as ``{"obs": ..., "context": ...}`` with ``obs_context_as_dict=True``. ``max_steps`` is the time
    limit (None: the original environment's); the environment owns it, so no ``TimeLimit`` wrapper is
    registered. ``info`` holds ``context_id`` (the set's id; -1 for resampled or given contexts),
    ``context`` (feature name → value) and the environment's own facts of the episode (its
    ``step_info``, e.g. the platformer's ``completed``, ``died`` and ``distance``). ``reset(options={"context": {...}})`` or
    ``options={"context_id": id}`` sets the context of one episode. ``changes``: how the context moves
    within an episode (``crl.Redraw``, ``crl.RandomWalk``, ``crl.Piecewise``, ``crl.StepFunction``;
    JAX environments only), applied by the core's step; the observation and ``info["context"]`` show
    the value the step ran under.

    ``copy_index``/``num_copies`` are for vector environments: copy ``i`` asks the selector for episode
    ``i + e * num_copies``, so the copies walk through the set together instead of all starting at its
    first context.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 50}

    def __init__(
        self,
        env_id: str | Env | HostEnv,
        contexts: Any = None,
        context_selector: str | Callable | None = None,
        obs_context_features: None | str | Sequence[str] = None,
        obs_context_as_dict: bool = False,
        obs_context_normalize: bool = False,
        obs_context_noise: float = 0.0,
        max_steps: int | None = None,
        render_mode: str | None = None,
        copy_index: int = 0,
        num_copies: int = 1,
        changes: Change | None = None,
        **env_kwargs: Any,
    ):
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(
                f"render_mode must be None or one of {RENDER_MODES}, got {render_mode!r}"
            )
        for name, value in (("copy_index", copy_index), ("num_copies", num_copies)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise ValueError(f"{name} must be an integer, got {value!r}")
        if not 0 <= copy_index < num_copies:
            raise ValueError(f"copy_index {copy_index} must lie in [0, num_copies={num_copies})")
        view = ContextView(
            obs_context_features, obs_context_as_dict, obs_context_normalize, obs_context_noise
        )
        made = build_setup(env_id, contexts, context_selector, view, max_steps, env_kwargs, changes)
        inner, self.schedule, obs_context = made.env, made.schedule, made.obs_context
        self.max_steps, self.changes = made.max_steps, made.changes
        self.backend = make_backend(inner, self.schedule, obs_context, self.max_steps, self.changes)
        self.contextrl_env = inner
        self.obs_context = obs_context
        self.context_space = inner.context_space
        self.obs_context_as_dict = obs_context_as_dict
        self.render_mode = render_mode
        # The world rectangle JAX renderings show; None fits each context (grids share one).
        self.render_world_box: tuple[float, float, float, float] | None = None
        self.copy_index, self.num_copies = int(copy_index), int(num_copies)
        # A host simulator renders through its own GL context (EGL for MuJoCo), which a pygame window
        # in the same process can break: host envs offer frames only.
        modes = ["rgb_array"] if isinstance(inner, HostEnv) else list(RENDER_MODES)
        if render_mode is not None and render_mode not in modes:
            raise ValueError(f"{inner.name} renders only in modes {modes}, got {render_mode!r}")
        self.metadata = {
            **self.metadata,
            "render_fps": render_fps(inner),
            "render_modes": modes,
        }
        self.action_space = self.backend.action_space
        self.observation_space = observation_space(
            self.backend.flat_space, self.backend.base_space, obs_context_as_dict
        )
        self._key_bits: np.ndarray | None = None
        self._info: dict[str, Any] = {}
        self._values_of_member: dict[int, dict[str, Any]] = {}
        self._window = None  # the "human" render window, opened on the first frame

    def _override(self, options: Mapping[str, Any] | None) -> tuple[np.ndarray, int] | None:
        """(context vector, set index or -1) asked for by ``reset(options=...)``, validated, or None."""
        if not options:
            return None
        return reset_override(self.schedule, options)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        override = self._override(options)
        super().reset(seed=seed)
        if seed is not None or self._key_bits is None:
            self._key_bits = run_key_bits(self.np_random)
            started = self.backend.begin(
                self._key_bits, self.copy_index, self.num_copies, override, self.np_random
            )
        else:
            started = self.backend.restart(override)
        obs, context_vector, index = started
        self._info = {
            "context_id": self.schedule.user_id(index),
            "context": self._values(index, context_vector),
        }
        if self.render_mode == "human":
            self.render()
        return self._observation(obs), self._fresh_info()

    def _observation(self, flat: np.ndarray) -> Any:
        if not self.obs_context_as_dict:
            return flat
        return split_observation(flat, self.observation_space)

    def _values(self, index: int, context_vector: np.ndarray) -> dict[str, Any]:
        """Feature values for ``info``; a set member's are converted once and remembered."""
        if index < 0:
            return self.schedule.values_dict(context_vector)
        if index not in self._values_of_member:
            self._values_of_member[index] = self.schedule.values_dict(context_vector)
        return self._values_of_member[index]

    def _fresh_info(self) -> dict[str, Any]:
        """A new info dict per call (users keep them; gymnasium's checker insists), with what the
        environment reports of its episode (``step_info``: e.g. completed, died, distance)."""
        info = {"context_id": self._info["context_id"], "context": dict(self._info["context"])}
        info.update(self.backend.step_info())
        return info

    def step(self, action):
        if self._key_bits is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        obs, reward, terminated, truncated = self.backend.advance(action)
        if self.changes is not None:  # the context this step ran under
            self._info["context"] = self.schedule.values_dict(self.backend.context_vector)
        if self.render_mode == "human":
            self.render()
        return self._observation(obs), reward, terminated, truncated, self._fresh_info()

    @property
    def context(self) -> dict[str, Any]:
        """The current episode's context (feature name → value), as of its last step."""
        return dict(self._info.get("context", {}))

    def _frame(self) -> np.ndarray:
        if isinstance(self.contextrl_env, HostEnv):
            return self.contextrl_env.render_frame()
        from contextrl.render import draw

        backend = self.backend  # a JAX env's state is the compiled programs' or its scalar physics'
        source = backend.simulator if isinstance(backend, HostBackend) else backend
        physics, context = source.physics_and_context()
        return draw(self.contextrl_env, physics, context, world_box=self.render_world_box)

    def __getattr__(self, name: str) -> Any:
        """A public attribute of the contextrl environment inside (``continuous``, which gymnasium's
        LunarLander heuristic reads from ``env.unwrapped``), as gymnasium's own environments have them."""
        inner = self.__dict__.get("contextrl_env")
        if name.startswith("_") or inner is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return getattr(inner, name)

    def render(self):
        """The current frame (``"rgb_array"``), or shown in a window (``"human"``, needs pygame)."""
        if self.render_mode is None:
            gymnasium.logger.warn(
                'render() needs render_mode="rgb_array" or "human" at construction'
            )
            return None
        if self._key_bits is None:
            raise gymnasium.error.ResetNeeded("call reset() before render()")
        frame = self._frame()
        if self.render_mode == "rgb_array":
            return frame
        if self._window is None:
            from contextrl.render.window import Window

            self._window = Window(self.contextrl_env.name, self.metadata["render_fps"])
        self._window.show(frame)
        return None

    def close(self):
        if self._window is not None:
            self._window.close()
            self._window = None
        self.backend.close()
        super().close()


def reset_override(schedule: ContextSchedule, options: Mapping[str, Any]) -> tuple[np.ndarray, int]:
    """(context vector, set index or -1) of ``reset(options={"context": ...} or {"context_id": id})``."""
    unknown = set(options) - {"context", "context_id"}
    if unknown:
        raise ValueError(f"unknown reset options {sorted(unknown)}; use 'context' or 'context_id'")
    if "context" in options and "context_id" in options:
        raise ValueError("give either options['context'] or options['context_id'], not both")
    space = schedule.space
    if "context" in options:
        context = options["context"]
        if isinstance(context, ContextBase):
            space.check(context)
            if context.batch_shape:
                raise ContextError("options['context'] must be one context, not a batch")
        elif isinstance(context, Mapping):
            context = space.make(**context)
        else:
            raise ContextError(
                "options['context'] must be a dict of feature values or a context, "
                f"got {type(context).__name__}"
            )
        return np.asarray(space.to_array(context), np.float32), -1
    context_id = options["context_id"]
    if schedule.resamples:
        raise ContextError(
            f"options['context_id']={context_id!r}: the contexts are drawn from a distribution at "
            "every reset, so there are no ids; give options['context'] (a dict of feature values)"
        )
    if context_id not in schedule.ids:
        raise ContextError(
            f"options['context_id']={context_id!r} is not an id of the context set "
            f"{list(schedule.ids)}"
        )
    index = schedule.ids.index(context_id)
    return np.asarray(space.to_array(schedule.contexts[index]), np.float32), index
