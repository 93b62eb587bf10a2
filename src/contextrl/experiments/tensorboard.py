"""``contextrl run … --log tensorboard``: training curves and test returns streamed to TensorBoard.

The logger follows the run directory rather than the executors: every second it looks for chunks that
finished since it last looked and writes their curves (``train/episode_return`` per trial, by
environment step) and test returns (``test/mean_return`` per trial), so it works with every protocol and
executor, and with ``--resume`` (chunks already logged are remembered in the run's log folder).
"""

from __future__ import annotations

import threading

import pandas as pd

from contextrl.experiments.runs import RunDir

LOGGED = ".logged"  # chunk numbers already written, one per line


class TensorBoardLog:
    """Writes finished chunks of ``run`` under ``RUN/tensorboard`` (one event folder per trial)."""

    def __init__(self, run: RunDir, every: float = 1.0):
        from tensorboardX import SummaryWriter  # optional: only --log tensorboard loads it

        self.run, self.every = run, every
        self.folder = run.path / "tensorboard"
        self.folder.mkdir(parents=True, exist_ok=True)
        self._writer_type = SummaryWriter
        self._writers: dict[str, object] = {}
        marker = self.folder / LOGGED
        self.logged = {int(x) for x in marker.read_text().split()} if marker.exists() else set()
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(
            target=self._follow, name="contextrl-tensorboard", daemon=True
        )

    def start(self) -> TensorBoardLog:
        self._thread.start()
        return self

    def _follow(self) -> None:
        while not self._stop.wait(self.every):
            self.sync()

    def _writer(self, trial: str):
        if trial not in self._writers:
            self._writers[trial] = self._writer_type(str(self.folder / trial))
        return self._writers[trial]

    def sync(self) -> None:
        """Write every chunk that finished and is not logged yet."""
        with self._lock:
            new = sorted(self.run.finished() - self.logged)
            for chunk in new:
                curves = self.run.path / "curves" / f"chunk-{chunk:04d}.parquet"
                if curves.exists():
                    for row in pd.read_parquet(curves).itertuples():
                        self._writer(row.trial).add_scalar(
                            "train/episode_return", row.episode_return, int(row.step)
                        )
                results = pd.read_parquet(self.run.result_path(chunk))
                for trial, group in results.groupby("trial"):
                    self._writer(trial).add_scalar("test/mean_return", group["return"].mean(), 0)
                self.logged.add(chunk)
            for writer in self._writers.values():
                writer.flush()
            if new:
                (self.folder / LOGGED).write_text("\n".join(map(str, sorted(self.logged))))

    def stop(self) -> None:
        """Stop following, write what is left and close the event files."""
        self._stop.set()
        self._thread.join()
        self.sync()
        for writer in self._writers.values():
            writer.close()
