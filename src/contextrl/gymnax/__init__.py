"""gymnax's API over every contextrl JAX environment: trainers written for gymnax run unchanged.

    import contextrl.gymnax as gymnax                      # was: import gymnax (0.0.x, PureJaxRL)
    env, params = gymnax.make("CartPole")                  # gymnax's ids work too: "CartPole-v1"
    obs, state = env.reset(key, params)
    obs, state, reward, done, info = env.step(key, state, action, params)

    import contextrl.gymnax.v1 as gymnax                   # was: import gymnax (1.0)
    obs, state, reward, terminated, truncated, info = env.step(key, state, action, params)

``step`` returns five values here, as gymnax 0.0.x did and as PureJaxRL and most published trainers
expect; gymnax 1.0's six (``terminated`` and ``truncated`` in place of ``done``) come from
``contextrl.gymnax.v1`` or ``make(id, step_api="1.0")``.

The params are the context (``CartPoleContext``): ``params.replace(length=0.8)`` gives another one, and a
batch from ``crl.sample`` is a batch of params, so ``jax.vmap(env.step)(keys, states, actions, batch)``
steps every copy under its own context. ``step`` is the core's ``Env.step``: when an episode ends
(terminated or at the time limit) the same call starts the next one under the same params, and ``info``
holds ``terminated``, ``truncated``, ``discount`` (0 at a termination, else 1) and
``final_observation`` (the last observation of the episode that ended), as in gymnax.

Where it differs from gymnax: the time limit is static configuration (``make(id, max_steps=...)``), not
``params.max_steps_in_episode`` (``contextrl.gymnax.v1`` has gymnax 1.0's, and its states have gymnax's
field names); derived constants (CartPole's ``total_mass``, ``polemass_length``) are
not params but computed from the context in every step, so they can never go stale. The spaces are
gymnax's own classes when gymnax is installed (so trainers' ``isinstance(space, spaces.Box)`` checks
pass), contextrl's otherwise (with gymnax's ``n``, ``shape``, ``dtype``, ``low``, ``high``, ``sample(key)``).
"""

from __future__ import annotations

import importlib.util
import re
from typing import Any

import jax
import jax.numpy as jnp

from contextrl.core.env import Env, EnvState
from contextrl.core.registry import make as make_env
from contextrl.core.registry import registered, spec
from contextrl.core.spaces import Box, Discrete

# gymnax's step conventions: 0.0.x returns (obs, state, reward, done, info); 1.0 returns (obs, state,
# reward, terminated, truncated, info).
STEP_APIS = ("0.x", "1.0")


class Environment:
    """A contextrl ``Env`` answering gymnax's calls; its params are the env's context type.

    ``reset`` and ``step`` are compiled once per environment (as gymnax's are), so a Python loop over
    them is fast too; inside a caller's ``jit`` they simply inline.
    """

    def __init__(self, env: Env, step_api: str = "0.x"):
        if step_api not in STEP_APIS:
            raise ValueError(
                f"step_api must be one of {list(STEP_APIS)} (gymnax 0.0.x's five values or 1.0's "
                f"six), got {step_api!r}"
            )
        self.env = env
        self.step_api = step_api
        self._action_space = gymnax_space(env.action_space)
        self._observation_space = gymnax_space(env.observation_space)
        self.reset = jax.jit(self._reset)
        self.step = jax.jit(self._step)

    def __repr__(self) -> str:
        return f"{type(self).__module__}.Environment({self.env!r})"

    @property
    def default_params(self):
        return self.env.default_context()

    @property
    def name(self) -> str:
        return self.env.name

    @property
    def num_actions(self) -> int:
        """The number of discrete actions, or the size of a continuous action."""
        space = self.env.action_space
        return space.n if isinstance(space, Discrete) else int(space.shape[0])

    def action_space(self, params: Any = None) -> Any:
        return self._action_space

    def observation_space(self, params: Any = None) -> Any:
        """The same for every params: wide enough for every context inside the bounds."""
        return self._observation_space

    def _reset(self, key: jax.Array, params: Any = None) -> tuple[jax.Array, EnvState]:
        state, timestep = self.env.reset(key, self._params(params))
        return timestep.obs, state

    def _step(self, key: jax.Array, state: EnvState, action: Any, params: Any = None) -> tuple:
        """(obs, state, reward, done, info), or with ``step_api="1.0"`` (obs, state, reward,
        terminated, truncated, info)."""
        state, timestep = self.env.step(key, state, action, self._params(params))
        info = {
            "terminated": timestep.terminated,
            "truncated": timestep.truncated,
            "discount": 1.0 - timestep.terminated.astype(jnp.float32),
            "final_observation": timestep.final_obs,
        }
        if self.step_api == "1.0":
            return (
                timestep.obs,
                state,
                timestep.reward,
                timestep.terminated,
                timestep.truncated,
                info,
            )
        return timestep.obs, state, timestep.reward, timestep.done, info

    def _params(self, params: Any):
        return self.default_params if params is None else params


def gymnax_space(space: Discrete | Box) -> Any:
    """gymnax's own space class for a contextrl space when gymnax is installed, so code written for
    gymnax that checks ``isinstance(space, gymnax.environments.spaces.Box)`` runs; the space unchanged
    otherwise."""
    if importlib.util.find_spec("gymnax") is None:
        return space
    from gymnax.environments import spaces

    if isinstance(space, Discrete):
        discrete = spaces.Discrete(space.n)
        discrete.dtype = space.dtype  # int32, the dtype the core steps with (gymnax's says int64)
        return discrete
    return spaces.Box(space.low, space.high, space.shape, space.dtype)


def _jax_ids() -> list[str]:
    return [env_id for env_id in registered() if not spec(env_id).host]


def make(env_id: str, step_api: str = "0.x", **kwargs: Any) -> tuple[Environment, Any]:
    """``(env, default_params)`` for a registered JAX environment (contextrl id, CARL alias or gymnax id
    such as ``"CartPole-v1"``). ``step_api``: "0.x" (five values) or "1.0" (six). Other keyword
    arguments go to ``crl.make`` (``max_steps``, ``obs_context_features``, ...)."""
    env = Environment(make_core(env_id, **kwargs), step_api)
    return env, env.default_params


def make_core(env_id: str, **kwargs: Any) -> Env:
    """The core environment behind a gymnax face for any of ``make``'s ids."""
    return make_env(core_id(env_id), **kwargs)


def core_id(env_id: str) -> str:
    """contextrl's id of a JAX environment (from its id, a CARL alias or a gymnax id); KeyError for an
    unknown one, ValueError for one that steps on the host."""
    try:
        env_spec = spec(env_id)
    except KeyError:
        unversioned = re.sub(r"-v\d+$", "", env_id)
        if unversioned == env_id:
            raise
        env_spec = spec(unversioned)
    if env_spec.host:
        raise ValueError(
            f"{env_spec.id} steps on the host, outside JAX, so it has no gymnax face; "
            f"JAX environments: {_jax_ids()}"
        )
    return env_spec.id


# gymnax's ids of the environments both libraries have, spelled as gymnax spells them
GYMNAX_IDS = {
    "CartPole": "CartPole-v1",
    "Pendulum": "Pendulum-v1",
    "Acrobot": "Acrobot-v1",
    "MountainCar": "MountainCar-v0",
    "MountainCarContinuous": "MountainCarContinuous-v0",
}
# What ``make`` serves, as gymnax's ``registered_envs`` is a list: first the environments gymnax has, by
# gymnax's ids in gymnax's order, then contextrl's other JAX environments.
registered_envs: list[str] = list(GYMNAX_IDS.values()) + [
    env_id for env_id in _jax_ids() if env_id not in GYMNAX_IDS
]
