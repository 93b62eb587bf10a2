"""The documentation site's Python blocks run as written: each page under docs/ runs its blocks in
order, in one namespace of its own (Sybil parses them, as test_readme.py does for the README; a block that
starts with ``>>>`` is a doctest), so a stale snippet fails the suite. The pages' ``contextrl run`` lines
are checked in test_readme_commands.py; `make docs` builds the site with ``mkdocs build --strict``."""

import doctest
import re

import pytest
from sybil import Sybil
from sybil.parsers.markdown import PythonCodeBlockParser

import contextrl as crl
from contextrl.agents import registry as agent_registry
from contextrl.core import registry
from tests.helpers import ROOT

DOCS = ROOT / "docs"
PARSER = PythonCodeBlockParser(doctest_optionflags=doctest.NORMALIZE_WHITESPACE)
PAGES = sorted(
    path
    for path in DOCS.rglob("*.md")
    if list(Sybil(parsers=[PARSER]).parse(path))  # pages without Python blocks have nothing to run
)


def test_the_site_has_python_blocks():
    assert len(PAGES) >= 10, PAGES


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(DOCS)) for p in PAGES])
def test_page_python_blocks_run(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # blocks that write files (checkpoints, GIFs) write them here
    # what a page registers (the context model's tutorial environment, the agents page's agent) is gone
    # after the page, so the tests that run over every registered environment or agent never see it
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    monkeypatch.setattr(registry, "_ALIASES", dict(registry._ALIASES))
    monkeypatch.setattr(agent_registry, "_AGENTS", dict(agent_registry._AGENTS))
    for example in Sybil(parsers=[PARSER]).parse(page):  # a failure names the page's line
        example.evaluate()


def test_every_family_has_a_page_with_its_generated_tables():
    """A new family shows up in the site: some page asks the docs build (tools/docs_hooks.py) for its
    feature tables, which are generated from the declarations."""
    families = {crl.spec(env_id).family for env_id in crl.registered()}
    markers = set()
    for page in DOCS.rglob("*.md"):
        markers |= set(re.findall(r"^<!-- contextrl:features (\w+) -->$", page.read_text(), re.M))
    assert families <= markers, f"families without a page: {sorted(families - markers)}"
