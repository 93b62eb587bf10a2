"""Tabular contextual MDPs with exact solutions: the paper's 3-state example and seeded random cMDPs.

Value iteration gives each context's optimal return; enumerating every deterministic context-oblivious
policy gives the best return a policy that ignores the context can reach. Their difference is the
optimality gap computed exactly, and a *conflict state* (reachable under two contexts whose optimal
action sets are disjoint there) is what the paper's theorem says forces a policy to need the context.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np


@dataclasses.dataclass(frozen=True)
class TabularCMDP:
    """``transitions[c, s, a, s']`` probabilities, ``rewards[c, s, a]``, a start state and a discount."""

    transitions: np.ndarray
    rewards: np.ndarray
    start: int = 0
    discount: float = 0.9
    name: str = "cmdp"

    def __post_init__(self):
        p, r = np.asarray(self.transitions, float), np.asarray(self.rewards, float)
        if (
            p.ndim != 4
            or p.shape[2] != r.shape[2]
            or p.shape[:3] != r.shape
            or p.shape[1] != p.shape[3]
        ):
            raise ValueError(
                f"transitions must be (contexts, states, actions, states) and rewards (contexts, "
                f"states, actions); got {p.shape} and {r.shape}"
            )
        if not np.allclose(p.sum(axis=-1), 1.0) or np.any(p < 0):
            raise ValueError("every transitions[c, s, a] must be a probability distribution")
        if not 0 <= self.start < p.shape[1]:
            raise ValueError(f"start state {self.start} is outside 0..{p.shape[1] - 1}")
        if not 0 <= self.discount < 1:
            raise ValueError(f"discount must lie in [0, 1), got {self.discount}")
        object.__setattr__(self, "transitions", p)
        object.__setattr__(self, "rewards", r)

    @property
    def shape(self) -> tuple[int, int, int]:
        """(contexts, states, actions)."""
        return self.rewards.shape


def value_iteration(cmdp: TabularCMDP, tolerance: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
    """Optimal values V*[c, s] and action values Q*[c, s, a] for every context, to ``tolerance``."""
    contexts, states, _ = cmdp.shape
    values = np.zeros((contexts, states))
    while True:
        q = cmdp.rewards + cmdp.discount * np.einsum("csat,ct->csa", cmdp.transitions, values)
        new = q.max(axis=-1)
        if np.max(np.abs(new - values)) < tolerance:
            return new, q
        values = new


def policy_values(cmdp: TabularCMDP, policy: np.ndarray) -> np.ndarray:
    """V^π[c, s] of a deterministic context-oblivious policy (action per state), by linear solve."""
    contexts, states, _ = cmdp.shape
    rows = np.arange(states)
    out = np.empty((contexts, states))
    for c in range(contexts):
        p = cmdp.transitions[c, rows, policy]  # (states, states)
        r = cmdp.rewards[c, rows, policy]
        out[c] = np.linalg.solve(np.eye(states) - cmdp.discount * p, r)
    return out


def reachable(cmdp: TabularCMDP, context: int) -> np.ndarray:
    """States reachable from the start under some action sequence in one context."""
    seen = np.zeros(cmdp.shape[1], bool)
    seen[cmdp.start] = True
    frontier = [cmdp.start]
    while frontier:
        state = frontier.pop()
        for nxt in np.flatnonzero(cmdp.transitions[context, state].max(axis=0) > 0):
            if not seen[nxt]:
                seen[nxt] = True
                frontier.append(nxt)
    return seen


@dataclasses.dataclass(frozen=True)
class Solution:
    """Exact results for one cMDP."""

    name: str
    optimal_returns: np.ndarray  # V*_c(start) per context
    oblivious_policy: tuple[int, ...]  # best deterministic context-oblivious policy
    oblivious_returns: np.ndarray  # its return per context
    conflict_states: tuple[int, ...]

    @property
    def optimality_gap(self) -> float:
        """E_c[G*(c) − G^π(c)] for the best context-oblivious policy; 0 iff one policy is optimal on all."""
        return float(np.mean(self.optimal_returns - self.oblivious_returns))


def solve(cmdp: TabularCMDP, tolerance: float = 1e-9) -> Solution:
    """Per-context optima, the best oblivious policy (exhaustive) and the conflict states."""
    contexts, states, actions = cmdp.shape
    values, q = value_iteration(cmdp)
    optimal = values[:, cmdp.start]
    best_policy, best_mean, best_returns = None, -np.inf, None
    for policy in itertools.product(range(actions), repeat=states):
        returns = policy_values(cmdp, np.asarray(policy))[:, cmdp.start]
        if returns.mean() > best_mean + 1e-12:
            best_policy, best_mean, best_returns = policy, returns.mean(), returns
    optimal_sets = q >= q.max(axis=-1, keepdims=True) - tolerance  # (contexts, states, actions)
    reach = np.stack([reachable(cmdp, c) for c in range(contexts)])
    conflicts = []
    for state in range(states):
        for a, b in itertools.combinations(range(contexts), 2):
            if (
                reach[a, state]
                and reach[b, state]
                and not np.any(optimal_sets[a, state] & optimal_sets[b, state])
            ):
                conflicts.append(state)
                break
    return Solution(cmdp.name, optimal, tuple(best_policy), best_returns, tuple(conflicts))


def three_state_cmdp(discount: float = 0.9) -> TabularCMDP:
    """The paper's Fig. 2: from S0, a0 → S1 (reward 10) and a1 → S2 (reward 1) in the original MDP;
    context 2 swaps where the actions lead (transition change); context 3 swaps the rewards of S1 and
    S2 (reward change). S1 and S2 are absorbing with reward 0."""
    p = np.zeros((3, 3, 2, 3))
    r = np.zeros((3, 3, 2))
    p[:, 1, :, 1] = 1.0
    p[:, 2, :, 2] = 1.0
    p[0, 0, 0, 1] = p[0, 0, 1, 2] = 1.0
    p[1, 0, 0, 2] = p[1, 0, 1, 1] = 1.0
    p[2, 0, 0, 1] = p[2, 0, 1, 2] = 1.0
    r[0, 0] = (10.0, 1.0)  # a0 enters S1 (10), a1 enters S2 (1)
    r[1, 0] = (1.0, 10.0)  # a0 now enters S2 (1), a1 enters S1 (10)
    r[2, 0] = (1.0, 10.0)  # a0 still enters S1, now worth 1; S2 worth 10
    return TabularCMDP(p, r, start=0, discount=discount, name="paper 3-state cMDP")


def random_cmdp(
    rng: np.random.Generator, contexts: int, states: int, actions: int, discount: float, name: str
) -> TabularCMDP:
    """A random cMDP: Dirichlet(1) transitions and U(0, 1) rewards per context, from a seeded Generator."""
    p = rng.dirichlet(np.ones(states), size=(contexts, states, actions))
    r = rng.uniform(0.0, 1.0, size=(contexts, states, actions))
    return TabularCMDP(p, r, start=0, discount=discount, name=name)
