"""The 95 % intervals cover the truth 95 % of the time: measured on synthetic experiments whose truth
is known (:mod:`contextrl.analysis.calibration`), in both designs a protocol can have."""

import pytest

from contextrl.analysis import calibration

# Two agents of one distribution, 10 seeds × 10 contexts, seed effect sd 20, context effect sd 50,
# noise sd 10, contexts drawn afresh in each experiment and resampled; 1,000 experiments, 1,000
# replicates each. Coverage measured with experiment seeds 0-4 (this test uses 0):
#   difference of means, shared × shared            0.938-0.954
#   probability of improvement, shared × shared     0.956-0.967
#   optimality gap, shared × independent            0.965-0.967
#   difference of means, independent × independent 0.936-0.945
#   probability of improvement, independent × ind.  0.937-0.948
#   optimality gap, independent × independent      0.936-0.945
# On the same experiments rliable's stratified percentile bootstrap covers far less where seeds are
# shared: benchmarks/interval_coverage.py.
SYNTHETIC = calibration.Synthetic(seeds=10, contexts=10)


@pytest.mark.parametrize(("statistic", "designs"), calibration.CASES)
def test_the_95_percent_interval_covers_the_truth_95_percent_of_the_time(statistic, designs):
    """Shared: one agent per seed tested on every context (its seed effect shared by all its
    contexts); independent: a run of its own per context and seed (the specialists)."""
    found = calibration.coverage(
        statistic, designs, experiments=1000, synthetic=SYNTHETIC, reps=1000, seed=0
    )
    assert 0.93 <= found <= 0.97, found
