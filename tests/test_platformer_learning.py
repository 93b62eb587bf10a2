"""PPO learns to finish short platformer levels from the tile observation."""

import learning  # tests/learning.py: the runs the learning tests share with their margin script
import numpy as np


def test_ppo_finishes_short_easy_levels():
    """PPO, 60k steps, four 24-column levels with narrow gaps and no enemies, seeds 0–3 in one
    vmapped call: how many of the four levels each seed's deterministic policy finishes (a return
    above 30 means the flag was reached; a death costs 20).

    MEASURED_PLATFORMER
    """
    statistics = learning.platformer_levels(range(4))
    finished = statistics["levels_finished"]
    assert PLATFORMER_ASSERT, finished
    assert np.all(statistics["first_updates"] < 25), statistics["first_updates"]  # failing at first
