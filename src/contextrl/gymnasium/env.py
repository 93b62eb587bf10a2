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

from contextrl.context.features import ContextBase, ContextError
from contextrl.core.env import Env
from contextrl.core.host import HostEnv
from contextrl.core.registry import spec
from contextrl.gymnasium.backends import HostBackend, JaxBackend, ScalarBackend, steps_on_host
from contextrl.gymnasium.schedule import ContextSchedule, resolve_contexts

RENDER_MODES = ("rgb_array",)


def build_env(
    env_id: str | Env | HostEnv, max_steps: int | None, env_kwargs: dict
) -> Env | HostEnv:
    """The contextrl environment behind an adapter: a registered id, or an env object as it is."""
    if isinstance(env_id, str):
        env_spec = spec(env_id)
        if env_spec.host:
            return env_spec.factory(**env_kwargs)
        return env_spec.factory(max_steps=max_steps, **env_kwargs)
    if env_kwargs:
        raise TypeError(f"unexpected arguments for an environment object: {sorted(env_kwargs)}")
    if isinstance(env_id, Env):
        return env_id if max_steps is None else dataclasses.replace(env_id, max_steps=max_steps)
    if isinstance(env_id, HostEnv):
        return env_id
    raise TypeError(f"env_id must be a registered id or a contextrl Env/HostEnv, got {env_id!r}")


def check_max_steps(max_steps: Any) -> None:
    if max_steps is None:
        return
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or max_steps < 1:
        raise ValueError(f"max_steps must be a positive integer or None, got {max_steps!r}")


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
    registered. ``info`` holds ``context_id`` (the set's id; -1 for resampled or given contexts) and
    ``context`` (feature name → value). ``reset(options={"context": {...}})`` or
    ``options={"context_id": id}`` sets the context of one episode.

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
        **env_kwargs: Any,
    ):
        check_max_steps(max_steps)
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(
                f"render_mode must be None or one of {RENDER_MODES}, got {render_mode!r}"
            )
        if not isinstance(obs_context_as_dict, bool):
            raise ContextError(
                f"obs_context_as_dict must be True or False, got {obs_context_as_dict!r}"
            )
        for name, value in (("copy_index", copy_index), ("num_copies", num_copies)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise ValueError(f"{name} must be an integer, got {value!r}")
        if not 0 <= copy_index < num_copies:
            raise ValueError(f"copy_index {copy_index} must lie in [0, num_copies={num_copies})")
        inner = build_env(env_id, max_steps, env_kwargs)
        self.schedule: ContextSchedule = resolve_contexts(
            inner.context_space, contexts, context_selector
        )
        obs_context = self.schedule.observation(
            obs_context_features, obs_context_normalize, obs_context_noise
        )
        if obs_context_as_dict and obs_context.hidden:
            raise ContextError(
                "obs_context_as_dict=True needs visible context features; set "
                'obs_context_features to "all", "varying" or a list of names'
            )
        if isinstance(inner, Env):
            inner = dataclasses.replace(inner, obs_context=obs_context)
            backend = ScalarBackend if steps_on_host(inner) else JaxBackend
            self.backend = backend(inner, self.schedule)
            self.max_steps = inner.max_steps
        else:
            self.max_steps = inner.default_max_steps if max_steps is None else int(max_steps)
            self.backend = HostBackend(inner, self.schedule, obs_context, self.max_steps)
        self.contextrl_env = inner
        self.obs_context = obs_context
        self.context_space = inner.context_space
        self.obs_context_as_dict = obs_context_as_dict
        self.render_mode = render_mode
        # The world rectangle JAX renderings show; None fits each context (grids share one).
        self.render_world_box: tuple[float, float, float, float] | None = None
        self.copy_index, self.num_copies = int(copy_index), int(num_copies)
        self.metadata = {**self.metadata, "render_fps": render_fps(inner)}
        self.action_space = self.backend.action_space
        self.observation_space = self._observation_space()
        self._key_bits: np.ndarray | None = None
        self._episode = 0
        self._info: dict[str, Any] = {}
        self._values_of_member: dict[int, dict[str, Any]] = {}

    def _observation_space(self) -> gymnasium.spaces.Space:
        flat = self.backend.flat_space
        if not self.obs_context_as_dict:
            return flat
        split = self.backend.base_size
        # A host env's original observation keeps its own space there (pixels: shape and dtype).
        base = getattr(self.backend, "base_space", None)
        if base is None:
            base = gymnasium.spaces.Box(flat.low[:split], flat.high[:split], dtype=np.float32)
        return gymnasium.spaces.Dict(
            {
                "obs": base,
                "context": gymnasium.spaces.Box(
                    flat.low[split:], flat.high[split:], dtype=np.float32
                ),
            }
        )

    def _observation(self, flat: np.ndarray):
        if not self.obs_context_as_dict:
            return flat
        split = self.backend.base_size
        obs_space = self.observation_space["obs"]
        obs = flat[:split].reshape(obs_space.shape).astype(obs_space.dtype, copy=False)
        return {"obs": obs, "context": flat[split:]}

    def _override(self, options: Mapping[str, Any] | None) -> np.ndarray | None:
        """The context vector asked for by ``reset(options=...)``, validated, or None."""
        if not options:
            return None
        unknown = set(options) - {"context", "context_id"}
        if unknown:
            raise ValueError(
                f"unknown reset options {sorted(unknown)}; use 'context' or 'context_id'"
            )
        if "context" in options and "context_id" in options:
            raise ValueError("give either options['context'] or options['context_id'], not both")
        space = self.context_space
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
            return np.asarray(space.to_array(context), np.float32)
        context_id = options["context_id"]
        if self.schedule.resamples or context_id not in self.schedule.ids:
            raise ContextError(
                f"options['context_id']={context_id!r} is not an id of the context set "
                f"{list(self.schedule.ids)}"
            )
        member = self.schedule.provider.contexts[self.schedule.ids.index(context_id)]
        return np.asarray(space.to_array(member), np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        override = self._override(options)
        super().reset(seed=seed)
        if seed is not None or self._key_bits is None:
            seed_key = jax.random.key(int(self.np_random.integers(2**32, dtype=np.uint64)))
            self._key_bits = np.asarray(jax.random.key_data(seed_key), np.uint32)
            self._episode = 0
        episode = self.copy_index + self._episode * self.num_copies
        self._episode += 1
        obs, context_vector, index = self.backend.start(
            self._key_bits, episode, self.np_random, override
        )
        if override is not None:
            index = -1
        self._info = {
            "context_id": self.schedule.user_id(index),
            "context": self._values(index, context_vector),
        }
        return self._observation(obs), self._fresh_info()

    def _values(self, index: int, context_vector: np.ndarray) -> dict[str, Any]:
        """Feature values for ``info``; a set member's are converted once and remembered."""
        if index < 0:
            return self.schedule.values_dict(context_vector)
        if index not in self._values_of_member:
            self._values_of_member[index] = self.schedule.values_dict(context_vector)
        return self._values_of_member[index]

    def _fresh_info(self) -> dict[str, Any]:
        """A new info dict per call (users keep them; gymnasium's checker insists), with what a host
        environment reports of its episode (``HostEnv.step_info``)."""
        info = {"context_id": self._info["context_id"], "context": dict(self._info["context"])}
        if isinstance(self.backend, HostBackend):
            info.update(self.contextrl_env.step_info())
        return info

    def step(self, action):
        if self._key_bits is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        obs, reward, terminated, truncated = self.backend.advance(action)
        return self._observation(obs), reward, terminated, truncated, self._fresh_info()

    @property
    def context(self) -> dict[str, Any]:
        """The current episode's context (feature name → value)."""
        return dict(self._info.get("context", {}))

    def render(self):
        if self.render_mode is None:
            gymnasium.logger.warn('render() needs render_mode="rgb_array" at construction')
            return None
        if self._key_bits is None:
            raise gymnasium.error.ResetNeeded("call reset() before render()")
        if isinstance(self.backend, HostBackend):
            return self.contextrl_env.render_frame()
        from contextrl.render import draw

        physics, context = self.backend.physics_and_context()
        return draw(self.contextrl_env, physics, context, world_box=self.render_world_box)

    def close(self):
        self.backend.close()
        super().close()
