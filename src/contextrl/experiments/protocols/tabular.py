"""The tabular protocol: contextual MDPs solved exactly, the paper's 3-state example and seeded random
cMDPs.

Value iteration gives each context's optimal return. Enumerating every deterministic context-oblivious
policy gives the best return such a policy reaches: the *deterministic gap* is exact. A stochastic
memoryless policy can do strictly better (two contexts that reward opposite actions: the best
deterministic policy earns ½, flipping a coin ≈ 0.91 with discount 0.9), and finding the best one is a
non-convex problem, so the *stochastic gap* is reported as what it is: an upper bound, reached by
exact-gradient ascent on softmax policies from many starts (the best deterministic policy among them).
A *conflict state* (reachable under two contexts whose optimal action sets are disjoint there) is what
the paper's theorem says forces a policy to need the context.
"""

from __future__ import annotations

import dataclasses
import itertools
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pandas as pd

from contextrl.analysis import metrics, plots
from contextrl.analysis.report import Section
from contextrl.analysis.scores import natural_key
from contextrl.experiments.protocol import Protocol, register_protocol
from contextrl.experiments.reports import figure
from contextrl.experiments.runs import Summary, write_parquet
from contextrl.experiments.spec import (
    CommonSpec,
    SpecError,
    check_int,
    check_number,
)


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


def _stochastic_search(
    cmdp: TabularCMDP, starts: np.ndarray, steps: int
) -> tuple[np.ndarray, np.ndarray]:
    """Gradient ascent on the mean start-state value of softmax context-oblivious policies.

    ``starts``: initial logits (starts × states × actions). Values are exact (a linear solve per
    context), so the gradient is exact too; returns the final policies and their mean returns.
    """
    transitions = jnp.asarray(cmdp.transitions, jnp.float32)
    rewards = jnp.asarray(cmdp.rewards, jnp.float32)
    states = cmdp.shape[1]

    def mean_return(logits):
        policy = jax.nn.softmax(logits, axis=-1)  # (states, actions)
        p = jnp.einsum("sa,csat->cst", policy, transitions)
        r = jnp.einsum("sa,csa->cs", policy, rewards)
        values = jnp.linalg.solve(jnp.eye(states) - cmdp.discount * p, r[..., None])[..., 0]
        return values[:, cmdp.start].mean()

    optimizer = optax.adam(0.1)

    def ascend(logits):
        def step(carry, _):
            logits, state = carry
            grad = jax.grad(mean_return)(logits)
            updates, state = optimizer.update(jax.tree_util.tree_map(jnp.negative, grad), state)
            return (optax.apply_updates(logits, updates), state), None

        (logits, _), _ = jax.lax.scan(step, (logits, optimizer.init(logits)), None, steps)
        return jax.nn.softmax(logits, axis=-1), mean_return(logits)

    policies, means = jax.jit(jax.vmap(ascend))(jnp.asarray(starts, jnp.float32))
    return np.asarray(policies, np.float64), np.asarray(means, np.float64)


def stochastic_policy_values(cmdp: TabularCMDP, policy: np.ndarray) -> np.ndarray:
    """V^π[c, s] of a stochastic context-oblivious policy π[s, a], by linear solve (float64)."""
    contexts, states, _ = cmdp.shape
    p = np.einsum("sa,csat->cst", policy, cmdp.transitions)
    r = np.einsum("sa,csa->cs", policy, cmdp.rewards)
    return np.stack(
        [np.linalg.solve(np.eye(states) - cmdp.discount * p[c], r[c]) for c in range(contexts)]
    )


@dataclasses.dataclass(frozen=True)
class Solution:
    """Results for one cMDP: exact per-context optima, the exact best deterministic context-oblivious
    policy, and the best stochastic one found (a lower bound on the best stochastic return)."""

    name: str
    optimal_returns: np.ndarray  # V*_c(start) per context
    oblivious_policy: tuple[int, ...]  # best deterministic context-oblivious policy
    oblivious_returns: np.ndarray  # its return per context
    conflict_states: tuple[int, ...]
    stochastic_policy: np.ndarray  # π[s, a], the best stochastic context-oblivious policy found
    stochastic_returns: np.ndarray  # its return per context

    @property
    def deterministic_gap(self) -> float:
        """E_c[G*(c) − G^π(c)] for the best deterministic context-oblivious π (exact)."""
        return float(np.mean(self.optimal_returns - self.oblivious_returns))

    @property
    def stochastic_gap_bound(self) -> float:
        """An upper bound on the gap of the best stochastic context-oblivious policy (≤ the
        deterministic gap; equal to the true gap when the search found the optimum)."""
        return float(np.mean(self.optimal_returns - self.stochastic_returns))


def solve(
    cmdp: TabularCMDP, tolerance: float = 1e-9, starts: int = 16, steps: int = 500
) -> Solution:
    """Per-context optima, the best deterministic oblivious policy (exhaustive), the best stochastic
    one found from ``starts`` seeded starts (plus the deterministic optimum), and the conflict states."""
    contexts, states, actions = cmdp.shape
    values, q = value_iteration(cmdp)
    optimal = values[:, cmdp.start]
    best_policy, best_mean, best_returns = None, -np.inf, None
    for policy in itertools.product(range(actions), repeat=states):
        returns = policy_values(cmdp, np.asarray(policy))[:, cmdp.start]
        if returns.mean() > best_mean + 1e-12:
            best_policy, best_mean, best_returns = policy, returns.mean(), returns
    rng = np.random.default_rng(0)
    logits = rng.normal(size=(starts, states, actions))
    logits[0] = 0.0  # the uniform policy
    logits[1] = 4.0 * np.eye(actions)[list(best_policy)]  # near the deterministic optimum
    policies, _ = _stochastic_search(cmdp, logits, steps)
    found = [stochastic_policy_values(cmdp, p)[:, cmdp.start] for p in policies]
    index = int(np.argmax([f.mean() for f in found]))
    stochastic_policy, stochastic_returns = policies[index], found[index]
    if stochastic_returns.mean() < best_mean:  # the search never reports worse than exhaustive
        stochastic_policy = np.eye(actions)[list(best_policy)]
        stochastic_returns = best_returns
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
    return Solution(
        cmdp.name,
        optimal,
        tuple(best_policy),
        best_returns,
        tuple(conflicts),
        stochastic_policy,
        stochastic_returns,
    )


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


def mirrored_cmdp(discount: float = 0.9) -> TabularCMDP:
    """Two contexts reward opposite actions: in S0 the right action reaches the absorbing S1 with
    reward 1, the wrong one stays in S0 with reward 0. Deterministic oblivious policies earn ½ on
    average; flipping a coin earns 0.5 / (1 − 0.5·discount) (≈ 0.91 at 0.9)."""
    p = np.zeros((2, 2, 2, 2))
    r = np.zeros((2, 2, 2))
    p[:, 1, :, 1] = 1.0
    p[0, 0, 0, 1] = p[0, 0, 1, 0] = 1.0  # context 0: a0 is right
    p[1, 0, 1, 1] = p[1, 0, 0, 0] = 1.0  # context 1: a1 is right
    r[0, 0, 0] = r[1, 0, 1] = 1.0
    return TabularCMDP(p, r, start=0, discount=discount, name="mirrored 2-context cMDP")


@dataclasses.dataclass(frozen=True)
class TabularSpec(CommonSpec):
    """Optimality gaps of tabular cMDPs solved exactly: the paper's 3-state cMDP, the mirrored
    two-context cMDP and ``num_random`` seeded random cMDPs. No agent is trained."""

    protocol: str = "tabular"
    env: str = "tabular"
    agent: str = "value_iteration"
    num_random: int = 8
    states: int = 4
    actions: int = 2
    contexts: int = 3
    discount: float = 0.9

    trains_agents = False
    unused_fields = dict.fromkeys(
        ("env", "agent", "agent_options", "variants", "max_steps", "backend"),
        "trains no agent on an environment",
    )
    vary_field = None

    def validate(self) -> None:
        super().validate()
        for field in ("num_random", "states", "actions", "contexts"):
            check_int(field, getattr(self, field), 1 if field != "num_random" else 0)
        if self.actions**self.states > 100_000:
            raise SpecError(
                f"states/actions: {self.actions}^{self.states} deterministic policies are too many "
                "to enumerate exactly (limit 100000)"
            )
        check_number("discount", self.discount, 0.0)
        if not self.discount < 1.0:
            raise SpecError(f"discount: must be below 1, got {self.discount!r}")


def tabular_frame(spec: TabularSpec) -> pd.DataFrame:
    """Solutions of the paper's 3-state cMDP, the mirrored cMDP and the seeded random cMDPs."""
    rng = np.random.default_rng(spec.seed)
    cmdps = [three_state_cmdp(spec.discount), mirrored_cmdp(spec.discount)] + [
        random_cmdp(rng, spec.contexts, spec.states, spec.actions, spec.discount, f"random-{i}")
        for i in range(spec.num_random)
    ]
    rows = []
    for cmdp in cmdps:
        solution = solve(cmdp)
        for context in range(cmdp.shape[0]):
            rows.append(
                {
                    "trial": cmdp.name,
                    "test_set": "tabular",
                    "context_index": context,
                    "optimal_return": float(solution.optimal_returns[context]),
                    "oblivious_return": float(solution.oblivious_returns[context]),
                    "stochastic_return": float(solution.stochastic_returns[context]),
                    "return": float(solution.stochastic_returns[context]),
                    "oblivious_policy": str(solution.oblivious_policy),
                    "stochastic_policy": str(
                        np.round(solution.stochastic_policy[:, 0], 3).tolist()
                    ),
                    "conflict_states": str(solution.conflict_states),
                }
            )
    return pd.DataFrame(rows)


def _sections(spec: TabularSpec, plan, results: pd.DataFrame, curves) -> list[Section]:
    rows, gaps = [], {}
    groups = sorted(results.groupby("trial", sort=False), key=lambda item: natural_key(item[0]))
    for name, group in groups:
        # exact returns: one "run" per context, so each policy's scores are a 1 × contexts matrix
        optimal = group["optimal_return"].to_numpy()
        deterministic = metrics.context_optimality_gap(group[["oblivious_return"]].T, optimal)
        stochastic = metrics.context_optimality_gap(group[["stochastic_return"]].T, optimal)
        gaps[name] = deterministic
        rows.append(
            {
                "cMDP": name,
                "contexts": len(group),
                "mean optimal return": float(group["optimal_return"].mean()),
                "best deterministic oblivious return": float(group["oblivious_return"].mean()),
                "deterministic gap (exact)": deterministic,
                "best stochastic oblivious return found": float(group["stochastic_return"].mean()),
                "stochastic gap (upper bound)": stochastic,
                "deterministic policy": group["oblivious_policy"].iloc[0],
                "stochastic policy π(a0|s)": group["stochastic_policy"].iloc[0],
                "conflict states": group["conflict_states"].iloc[0],
            }
        )
    text = [
        "Value iteration gives each context's optimal return. The deterministic gap is exact: every "
        "deterministic context-oblivious policy is enumerated. A stochastic oblivious policy can do "
        "better (see the mirrored cMDP); the best one found by exact-gradient ascent from 16 starts "
        "gives an upper bound on the stochastic gap (the true stochastic gap lies between 0 and this "
        "bound, and equals it when the search found the optimum). A gap above zero goes with a "
        "conflict state (reachable in two contexts whose optimal actions differ there), as the "
        f"paper's theorem says. Discount {spec.discount}."
    ]
    bars = figure(
        "tabular-gaps",
        plots.bars(
            gaps,
            ylabel="deterministic optimality gap",
            title="Optimality gap of deterministic context-oblivious policies (exact)",
        ),
        "Exact deterministic optimality gap per cMDP",
    )
    return [Section("Tabular cMDPs", text, [("Solutions", rows)], [bars])]


def _execute(spec: TabularSpec, run, plan, *, executor, address, max_chunks, progress, verbose):
    """Solve every cMDP here (seconds; no executor needed) unless already done."""
    if run.finished():
        return Summary([], [0], [], [], 0.0)
    start = time.perf_counter()
    write_parquet(run.result_path(0), tabular_frame(spec))
    return Summary([0], [], [], [], time.perf_counter() - start)


def _progress_row(spec: TabularSpec, run, plan, results, failures) -> dict:
    return {"cMDPs": results["trial"].nunique() if not results.empty else 0}


register_protocol(Protocol(TabularSpec, _sections, execute=_execute, progress_row=_progress_row))
