"""Agents by name: what an experiment needs to build, train and run any agent, so protocols never
compare agent names.

    from contextrl.agents import Agent, register_agent, ppo
    register_agent(Agent("ppo_wide", ppo.PPOConfig, ppo.make_train, ppo.make_policy,
                         defaults=lambda env: {"hidden_sizes": (256, 256)}))

An agent is a config dataclass (with ``validate()`` and a ``context_obs`` field), ``make_train(config,
env, train_contexts) -> train(key, contexts)`` and ``make_policy(config, env, train_contexts) ->
policy(params, obs, ctx, key)``. ``defaults(env_name)`` gives per-environment settings (the paper's)
that the user's options override. An agent without ``make_train`` is not trained (the random baseline).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

from contextrl.agents import dqn, ppo, sac
from contextrl.agents.networks import ConfigError
from contextrl.core.spaces import Box, Discrete

CONTEXT_OPTION = "context_obs"  # the config field that says how an agent sees the context


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

    @property
    def trained(self) -> bool:
        return self.make_train is not None

    def option_names(self) -> list[str]:
        if self.config_type is None:
            return []
        return sorted(f.name for f in dataclasses.fields(self.config_type))

    def config(self, env_name: str, options: Mapping[str, Any], context_obs: str = "hidden"):
        """The validated config: the environment's defaults, then ``options``, then the visibility."""
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
        values = {**self.defaults(env_name), **options, CONTEXT_OPTION: context_obs}
        try:
            config = self.config_type(**values)
        except TypeError as error:
            raise ConfigError(f"{self.name}: {error}") from None
        config.validate()
        return config

    def check_env(self, env) -> None:
        """Refuse an environment whose action space this agent cannot act in."""
        kind = "discrete" if isinstance(env.action_space, Discrete) else "continuous"
        if kind not in self.actions or (
            kind == "continuous" and not isinstance(env.action_space, Box)
        ):
            raise ConfigError(
                f"the {self.name} agent acts in {' or '.join(self.actions)} action spaces; "
                f"{env.name} has {env.action_space!r}"
            )


def _random_policy(config, env, train_contexts) -> Callable:
    """Uniform random actions: the no-learning baseline every report compares against."""

    def policy(params, obs, ctx, key):
        return env.action_space.sample(key)

    return policy


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


register_agent(Agent("ppo", ppo.PPOConfig, ppo.make_train, ppo.make_policy, doc="PPO (clipped)"))
register_agent(
    Agent("dqn", dqn.DQNConfig, dqn.make_train, dqn.make_policy, actions=("discrete",), doc="DQN")
)
register_agent(
    Agent(
        "c51",
        dqn.DQNConfig,
        dqn.make_train,
        dqn.make_policy,
        defaults=_c51_defaults,
        actions=("discrete",),
        doc="C51 (distributional DQN; the paper's settings where it has them)",
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
        doc="SAC (the paper's settings where it has them)",
    )
)
register_agent(Agent("random", None, None, _random_policy, doc="uniform random actions"))
