"""The README's ``contextrl run`` lines are accepted as written: each one that starts a new run is
checked with ``--dry-run --no-calibration``, which validates the whole spec exactly as the run does and
trains nothing. (The README's Python blocks run in test_readme.py; `make run`
itself runs in .ci/run after the suite.)"""

import re
import shlex
from pathlib import Path

import pytest

from contextrl.cli import main

ROOT = Path(__file__).resolve().parents[1]


def new_run_commands() -> list[str]:
    """Every ``contextrl run`` line of the README's bash blocks, without its comment, except those that
    continue or read an earlier run (``--resume``, a ``runs/…`` placeholder)."""
    blocks = re.findall(r"```bash\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
    commands = []
    for block in blocks:
        for line in block.splitlines():
            command = line.split(" #")[0].strip()
            if command.startswith("contextrl run") and "--resume" not in command:
                if "…" not in command:
                    commands.append(command)
    return commands


def test_the_readme_shows_run_commands():
    assert len(new_run_commands()) >= 8


@pytest.mark.parametrize("command", new_run_commands())
def test_readme_run_command_is_valid(command, monkeypatch, capsys):
    monkeypatch.chdir(ROOT)  # the README's paths (examples/…) are relative to the project
    argv = shlex.split(command)[1:]
    assert main([*argv, "--dry-run", "--no-calibration"]) == 0, capsys.readouterr().err
    assert "trials:" in capsys.readouterr().out
