"""The README's Python blocks run as written, in order, in one namespace (Sybil parses them; a block
that starts with ``>>>`` is a doctest), so a stale snippet fails the suite. Its ``contextrl run``
lines are checked in test_readme_commands.py."""

import doctest
from pathlib import Path

from sybil import Sybil
from sybil.parsers.markdown import PythonCodeBlockParser

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_blocks_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the blocks write checkpoints under runs/
    parser = PythonCodeBlockParser(doctest_optionflags=doctest.NORMALIZE_WHITESPACE)
    examples = list(Sybil(parsers=[parser]).parse(README))
    assert len(examples) >= 12
    for example in examples:  # a failure names the README line of its block
        example.evaluate()
