"""Agents by name: what an experiment needs to build, train and run any agent, so protocols never
compare agent names.

    from contextrl.agents import Agent, register_agent, ppo
    register_agent(Agent("ppo_wide", ppo.PPOConfig, ppo.make_train, ppo.make_policy,
                         defaults=lambda env: {"hidden_sizes": (256, 256)}))

An agent is a config dataclass (with ``validate()`` and a ``variant`` field, one of :data:`VARIANTS`),
``make_train(config, env, train_contexts) -> train(key, contexts)`` and ``make_policy(config, env,
train_contexts) -> policy(params, obs, ctx, key)``. ``defaults(env_name)`` gives per-environment
settings (the paper's) that the user's options override. An agent without ``make_train`` is not trained
(the random baseline). For host environments (dm_control, Box2D…) an agent adds ``train_host(config,
env_id, train_contexts, key, seed=..., init_params=None, **env_kwargs)`` on the shared host collector
(``init_params``: parameters to continue training, for population-based tuning), and its
``make_policy`` returns a :class:`~contextrl.agents.common.Policy`, whose ``act(params, obs,
context_input, key)`` acts on the batches of a host loop. ``init_params(config, env, train_contexts,
key)`` (optional) gives fresh parameters, so population-based tuning (the hpo protocol) compiles one
training function that always continues given parameters.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import jax

from contextrl.agents import dqn, ppo, sac
from contextrl.agents.common import Policy
from contextrl.agents.networks import ContextInput
from contextrl.agents.validation import ConfigError
from contextrl.core.spaces import Box, Discrete


@dataclasses.dataclass(frozen=True)
class Agent:
    """A registered agent: its config type and how to train and run it."""

    name: str
    config_type: type | None
    make_train: Callable | None
    make_policy: Callable
    defaults: Callable[[str], Mapping[str, Any]] = lambda env_name: {}
    actions: tuple[str, ...] = ("discrete", "continuous")
    doc: str = ""
    train_host: Callable | None = None
    init_params: Callable | None = None

    @property
    def trained(self) -> bool:
        return self.make_train is not None

    @property
    def runs_on_host(self) -> bool:
        return self.train_host is not None or not self.trained

    def option_names(self) -> list[str]:
        if self.config_type is None:
            return []
        return sorted(f.name for f in dataclasses.fields(self.config_type))

    def config(self, env_name: str, options: Mapping[str, Any], variant: str = "hidden"):
        """The validated config: the environment's defaults, then ``options``, then the variant."""
        options = dict(options)
        if self.config_type is None:
            if options:
                raise ConfigError(f"the {self.name} agent takes no options, got {options}")
            return None
        unknown = sorted(set(options) - set(self.option_names()))
        if unknown:
            raise ConfigError(
                f"unknown {self.name} option(s) {unknown}; valid: {self.option_names()}"
            )
        values = {**self.defaults(env_name), **options, "variant": variant}
        try:
            config = self.config_type(**values)
        except TypeError as error:
            raise ConfigError(f"{self.name}: {error}") from None
        config.validate()
        return config

    def check_action_space(self, env, host: bool = False) -> None:
        """Refuse an environment whose action space this agent cannot act in."""
        if host and not self.runs_on_host:
            raise ConfigError(
                f"the {self.name} agent has no host training loop, so it cannot train {env.name} "
                f"(a host environment); agents that can: {host_agents()}"
            )
        space = env.action_space  # contextrl's or gymnasium's (host environments)
        kind = "discrete" if hasattr(space, "n") else "continuous"
        if kind not in self.actions or (kind == "continuous" and not hasattr(space, "low")):
            raise ConfigError(
                f"the {self.name} agent acts in {' or '.join(self.actions)} action spaces; "
                f"{env.name} has {space!r}"
            )


def _random_policy(config, env, train_contexts) -> Policy:
    """Uniform random actions, the no-learning baseline every report compares against: one
    observation of a JAX environment at a time, or a batch of a host environment's (gymnasium
    spaces)."""
    space = env.action_space
    if isinstance(space, (Box, Discrete)):

        def act(params, obs, context_vector, key):
            return space.sample(key)

    elif hasattr(space, "n"):

        def act(params, obs, context_vector, key):
            return jax.random.randint(key, (len(obs),), 0, int(space.n))

    else:

        def act(params, obs, context_vector, key):
            shape = (len(obs), *space.low.shape)
            return jax.random.uniform(key, shape, minval=space.low, maxval=space.high)

    return Policy(act, ContextInput(), env.context_space)


def _c51_defaults(env_name: str) -> dict[str, Any]:
    if env_name in dqn.PAPER_C51:
        return dataclasses.asdict(dqn.paper_config(env_name))
    return {"distributional": True}


def _sac_defaults(env_name: str) -> dict[str, Any]:
    if env_name in sac.PAPER_SAC:
        return dataclasses.asdict(sac.paper_config(env_name))
    return {}


_AGENTS: dict[str, Agent] = {}


def register_agent(agent: Agent, *, replace: bool = False) -> Agent:
    """Make ``agent`` available by name to every protocol (``agent: NAME`` in a spec)."""
    if not isinstance(agent, Agent):
        raise TypeError(f"register_agent takes an Agent, got {type(agent).__name__}")
    if agent.name in _AGENTS and not replace:
        raise ValueError(f"an agent named {agent.name!r} is already registered (replace=True)")
    _AGENTS[agent.name] = agent
    return agent


def get_agent(name: str) -> Agent:
    """The registered agent ``name``; an unknown name lists the registered ones."""
    if name not in _AGENTS:
        raise KeyError(f"unknown agent {name!r}; registered: {registered_agents()}")
    return _AGENTS[name]


def registered_agents() -> list[str]:
    return sorted(_AGENTS)


def host_agents() -> list[str]:
    """Agents that can train (or act in) host environments."""
    return sorted(name for name, agent in _AGENTS.items() if agent.runs_on_host)


register_agent(
    Agent(
        "ppo",
        ppo.PPOConfig,
        ppo.make_train,
        ppo.make_policy,
        doc="PPO (clipped)",
        train_host=ppo.train_gymnasium,
        init_params=ppo.init_params,
    )
)
register_agent(
    Agent(
        "dqn",
        dqn.DQNConfig,
        dqn.make_train,
        dqn.make_policy,
        actions=("discrete",),
        doc="DQN",
        train_host=dqn.train_gymnasium,
        init_params=dqn.init_params,
    )
)
register_agent(
    Agent(
        "c51",
        dqn.DQNConfig,
        dqn.make_train,
        dqn.make_policy,
        defaults=_c51_defaults,
        actions=("discrete",),
        doc="C51 (distributional DQN; the authors' settings where their configs have them)",
        train_host=dqn.train_gymnasium,
        init_params=dqn.init_params,
    )
)
register_agent(
    Agent(
        "sac",
        sac.SACConfig,
        sac.make_train,
        sac.make_policy,
        defaults=_sac_defaults,
        actions=("continuous",),
        doc="SAC (the authors' settings where their configs have them)",
        train_host=sac.train_gymnasium,
        init_params=sac.init_params,
    )
)
register_agent(
    Agent(
        "random",
        None,
        None,
        _random_policy,
        doc="uniform random actions",
    )
)
