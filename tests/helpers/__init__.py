"""What several test files share: the runs of the learning tests, hand-built result rows, a report's
tables read back, Brax's own rollouts, and the project's root folder."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
