"""More seeds for a finished run: the same results as a fresh run with that count, crash or not."""

import os

import pandas as pd
import pytest

from contextrl.experiments import RunDir, resume, run_experiment
from contextrl.experiments import more_seeds as more_seeds_module
from contextrl.experiments.more_seeds import JOURNAL, add_seeds
from contextrl.experiments.spec import SpecError

SPEC = {
    "protocol": "visibility",
    "agent": "random",
    "variants": ["hidden", "concat_all"],
    "seeds": 2,
    "batch_size": 1,
    "max_steps": 20,
    "eval_episodes": 2,
    "bootstrap_reps": 100,
    "num_train_contexts": 2,
    "num_test_contexts": 3,
}
COLUMNS = ["trial", "context_index", "return"]


def run(path, **fields) -> RunDir:
    return run_experiment({**SPEC, **fields}, out=path, progress=False, report=False)[0]


def test_added_seeds_give_what_a_fresh_run_with_that_count_gives_even_after_a_crash(
    tmp_path, monkeypatch
):
    fresh = run(tmp_path / "fresh", seeds=3)
    kept = run(tmp_path / "kept")
    concat_s0 = (kept.path / "results" / "chunk-0002.parquet").read_bytes()
    add_seeds(kept, 3)
    assert kept.spec().seeds == 3 and kept.finished() == {0, 1, 3, 4}  # hidden-s2 is chunk 2 now
    assert (kept.path / "results" / "chunk-0003.parquet").read_bytes() == concat_s0
    _, summary = resume(kept.path, progress=False, report=False)
    assert summary.skipped == [0, 1, 3, 4] and summary.ran == [2, 5]
    pd.testing.assert_frame_equal(kept.results()[COLUMNS], fresh.results()[COLUMNS])

    # killed after the first file was moved: the resume finishes the renumbering, then the run
    crashed = run(tmp_path / "crashed")
    replace = os.replace

    def one_move_then_killed(source, target):
        replace(source, target)
        raise KeyboardInterrupt

    monkeypatch.setattr(more_seeds_module.os, "replace", one_move_then_killed)
    with pytest.raises(KeyboardInterrupt):
        add_seeds(crashed, 3)
    monkeypatch.setattr(more_seeds_module.os, "replace", replace)
    assert (crashed.path / JOURNAL).exists() and crashed.spec().seeds == 2
    resume(crashed.path, progress=False, report=False)
    assert not (crashed.path / JOURNAL).exists()
    pd.testing.assert_frame_equal(crashed.results()[COLUMNS], fresh.results()[COLUMNS])


def test_chunks_that_stay_whole_take_more_seeds_and_ones_that_would_regroup_refuse(tmp_path):
    """A chunk holding all of a variant's seeds stays whole: the larger plan takes its size and puts
    the new seeds in chunks after it. A chunk of some seeds only would regroup: refused."""
    whole = run(tmp_path / "whole", batch_size=16)  # [s0, s1] per variant
    add_seeds(whole, 3)
    assert (whole.spec().seeds, whole.spec().batch_size) == (3, 2)  # [s0, s1], [s2]
    assert whole.finished() == {0, 2}
    resume(whole.path, progress=False, report=False)
    fresh = run(tmp_path / "fresh", seeds=3, batch_size=2)
    pd.testing.assert_frame_equal(whole.results()[COLUMNS], fresh.results()[COLUMNS])

    batched = run(tmp_path / "batched", seeds=3, batch_size=2)  # [s0, s1], [s2] per variant
    files = sorted(p.name for p in (batched.path / "results").iterdir())
    with pytest.raises(SpecError, match=r"chunk 1 \(\S+-hidden-s2\) is not a chunk of the plan"):
        add_seeds(batched, 4)  # [s0, s1], [s2, s3]
    with pytest.raises(SpecError, match="seeds: 3 for .*; give an integer above its 3"):
        add_seeds(batched, 3)
    assert sorted(p.name for p in (batched.path / "results").iterdir()) == files
    assert batched.spec().seeds == 3 and not (batched.path / JOURNAL).exists()
