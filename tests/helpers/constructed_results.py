"""Result rows built by hand, as a run writes them: tests of reports and commands give each trial its
returns and check what is computed from them, without training anything."""

from __future__ import annotations

import numpy as np
import pandas as pd

from contextrl.experiments import expand


def result_rows(spec, returns: dict[str, np.ndarray], **extra) -> pd.DataFrame:
    """The rows a run writes for each trial of ``returns`` (trial id → return per test context)."""
    plan = expand(spec)
    frames = []
    for trial in plan.trials:
        if trial.id not in returns:
            continue
        test = plan.sets[trial.test_set]
        frames.append(
            pd.DataFrame(
                {
                    "trial": trial.id,
                    "kind": trial.kind,
                    "variant": trial.variant,
                    "seed": trial.seed,
                    "train_set": trial.train_set,
                    "test_set": trial.test_set,
                    "context_index": np.arange(len(test)),
                    **{
                        f"ctx.{n}": np.asarray(getattr(test.contexts, n))
                        for n in spec.space().names
                    },
                    **{k: list(v) for k, v in test.labels.items()},
                    "return": np.asarray(returns[trial.id], dtype=float),
                    **extra,
                }
            )
        )
    return pd.concat(frames, ignore_index=True)
