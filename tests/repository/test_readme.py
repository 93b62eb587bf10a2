"""The README's Python blocks run as written, in order, in one namespace (Sybil parses them; a block
that starts with ``>>>`` is a doctest), so a stale snippet fails the suite. Its ``contextrl run``
lines are checked in test_readme_commands.py; the documentation site's blocks run in test_docs.py."""

import doctest

from sybil import Sybil
from sybil.parsers.markdown import PythonCodeBlockParser

from tests.helpers import ROOT

README = ROOT / "README.md"


def test_readme_python_blocks_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a block that writes files writes them here
    parser = PythonCodeBlockParser(doctest_optionflags=doctest.NORMALIZE_WHITESPACE)
    examples = list(Sybil(parsers=[parser]).parse(README))
    assert len(examples) >= 6  # quickstart, bad input, gymnasium/SB3, CARL, gymnax, agents
    for example in examples:  # a failure names the README line of its block
        example.evaluate()
