"""Tabular cMDPs: exact deterministic gaps, stochastic gap bounds, the theorem on conflict states."""

import numpy as np
import pytest

from contextrl.experiments.protocols.tabular import (
    TabularCMDP,
    mirrored_cmdp,
    policy_values,
    random_cmdp,
    solve,
    three_state_cmdp,
    value_iteration,
)

pytestmark = pytest.mark.quick


def test_three_state_example_gap_is_exact():
    solution = solve(three_state_cmdp())
    # every context has an optimal return of 10 (the reward is collected on the first step)
    np.testing.assert_allclose(solution.optimal_returns, [10.0, 10.0, 10.0])
    # a0 everywhere earns 10, 1, 1; a1 earns 1, 10, 10: the best oblivious choice is a1 in S0
    assert solution.oblivious_policy[0] == 1
    np.testing.assert_allclose(solution.oblivious_returns, [1.0, 10.0, 10.0])
    assert solution.deterministic_gap == pytest.approx(3.0)
    # mixing p of a0 earns (21 − 9p)/3 on average: linear, so no stochastic policy beats a1
    assert solution.stochastic_gap_bound == pytest.approx(3.0, abs=1e-4)
    assert solution.conflict_states == (0,)


def test_stochastic_oblivious_policy_beats_every_deterministic_one():
    solution = solve(mirrored_cmdp(0.9))
    np.testing.assert_allclose(solution.optimal_returns, [1.0, 1.0])
    assert solution.deterministic_gap == pytest.approx(0.5)  # one context solved, one never
    # by hand: a coin flip in S0 earns V = ½ + ½·0.9·V, V = 0.5 / 0.55 in both contexts
    coin = 0.5 / (1 - 0.5 * 0.9)
    np.testing.assert_allclose(solution.stochastic_returns, [coin, coin], atol=1e-4)
    np.testing.assert_allclose(solution.stochastic_policy[0], [0.5, 0.5], atol=1e-2)
    assert solution.stochastic_gap_bound == pytest.approx(1 - coin, abs=1e-4)


def test_identical_contexts_have_no_gap_and_no_conflict():
    base = three_state_cmdp()
    same = TabularCMDP(
        np.repeat(base.transitions[:1], 3, 0), np.repeat(base.rewards[:1], 3, 0), discount=0.9
    )
    solution = solve(same)
    assert solution.deterministic_gap == pytest.approx(0.0, abs=1e-9)
    assert solution.stochastic_gap_bound == pytest.approx(0.0, abs=1e-9)
    assert solution.conflict_states == ()


def test_gap_implies_conflict_on_random_cmdps():
    rng = np.random.default_rng(0)
    for i in range(6):
        solution = solve(
            random_cmdp(rng, contexts=3, states=4, actions=2, discount=0.9, name=str(i))
        )
        assert solution.deterministic_gap >= solution.stochastic_gap_bound >= -1e-9
        if solution.stochastic_gap_bound > 1e-6:
            assert solution.conflict_states  # the theorem: a gap needs a conflict state


def test_value_iteration_agrees_with_policy_evaluation_of_greedy_policy():
    cmdp = random_cmdp(np.random.default_rng(1), 2, 5, 3, 0.8, "r")
    values, q = value_iteration(cmdp)
    for c in range(2):
        greedy = q[c].argmax(axis=-1)
        exact = policy_values(
            TabularCMDP(cmdp.transitions[c : c + 1], cmdp.rewards[c : c + 1], discount=0.8), greedy
        )
        np.testing.assert_allclose(exact[0], values[c], atol=1e-8)


def test_random_cmdps_are_reproducible_from_the_seed():
    a = random_cmdp(np.random.default_rng(5), 2, 3, 2, 0.9, "a")
    b = random_cmdp(np.random.default_rng(5), 2, 3, 2, 0.9, "b")
    np.testing.assert_array_equal(a.transitions, b.transitions)


def test_invalid_cmdp_is_refused():
    cmdp = three_state_cmdp()
    with pytest.raises(ValueError, match="probability"):
        TabularCMDP(cmdp.transitions * 2, cmdp.rewards)
    with pytest.raises(ValueError, match="discount"):
        TabularCMDP(cmdp.transitions, cmdp.rewards, discount=1.0)
