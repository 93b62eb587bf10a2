"""The ``contextrl run`` lines of the README and of the documentation site's pages are accepted as
written: each one that starts a new run is checked with ``--dry-run``, which validates
the whole spec exactly as the run does and trains nothing. (The Python blocks run in test_readme.py and
test_docs.py; `make run` itself runs in .ci/run after the suite.)"""

import re
import shlex

import pytest

from contextrl.cli import main
from tests.helpers import ROOT

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def new_run_commands() -> list[tuple[str, str]]:
    """(page, command) for every ``contextrl run`` line of the pages' bash blocks, without its comment,
    except those that continue or read an earlier run (``--resume``, a ``runs/…`` placeholder); a
    command shown on several pages is checked once, under the first."""
    commands, seen = [], set()
    for page in PAGES:
        blocks = re.findall(r"```bash\n(.*?)```", page.read_text(), re.S)
        for block in blocks:
            for line in block.splitlines():
                command = line.split(" #")[0].strip()
                if command.startswith("contextrl run") and "--resume" not in command:
                    if "…" not in command and command not in seen:
                        seen.add(command)
                        commands.append((str(page.relative_to(ROOT)), command))
    return commands


def test_the_pages_show_run_commands():
    pages = {page for page, _ in new_run_commands()}
    assert "README.md" in pages and len(pages) >= 5, pages
    assert len(new_run_commands()) >= 15


@pytest.mark.parametrize(
    "command", [c for _, c in new_run_commands()], ids=[f"{p}: {c}" for p, c in new_run_commands()]
)
def test_run_command_is_valid(command, monkeypatch, capsys):
    monkeypatch.chdir(ROOT)  # the pages' paths (examples/…) are relative to the project
    argv = shlex.split(command)[1:]
    assert main([*argv, "--dry-run"]) == 0, capsys.readouterr().err
    assert "trials:" in capsys.readouterr().out
