"""The documentation site's Python blocks run as written: each page under docs/ runs its blocks in
order, in one namespace of its own (Sybil parses them, as test_readme.py does for the README; a block that
starts with ``>>>`` is a doctest), so a stale snippet fails the suite. The pages' ``contextrl run`` lines
are checked in test_readme_commands.py; `make docs` builds the site with ``mkdocs build --strict``."""

import doctest
import importlib
import re

import pytest
from sybil import Sybil
from sybil.parsers.markdown import PythonCodeBlockParser

import contextrl as crl
from contextrl.agents import registry as agent_registry
from contextrl.cli import build_parser
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


def test_every_command_the_pages_name_exists():
    """A ``contextrl X`` in inline code or in a bash block names a real subcommand, so a page never
    sends a reader to a command that is gone."""
    subcommands = set(build_parser()._subparsers._group_actions[0].choices)
    named = {}
    for page in [ROOT / "README.md", *DOCS.rglob("*.md")]:
        text = page.read_text()
        code = re.findall(r"`contextrl ([a-z][\w-]*)", text)
        for block in re.findall(r"```bash\n(.*?)```", text, re.S):
            code += re.findall(r"^contextrl ([a-z][\w-]*)", block, re.M)
        named |= {name: page.name for name in code}
    unknown = {name: page for name, page in named.items() if name not in subcommands}
    assert not unknown, f"commands that do not exist: {unknown}"


def test_a_function_named_in_the_prose_says_where_it_is_imported_from():
    """A function of a subpackage (not ``crl.``) called in a page's inline code is imported somewhere on
    that page, so a reader can use it without searching the source."""
    modules = ["agents", "experiments", "analysis", "gymnasium", "carl"]
    homes = {}
    for module in modules:
        for name in getattr(importlib.import_module(f"contextrl.{module}"), "__all__", ()):
            if not hasattr(crl, name):
                homes.setdefault(name, module)
    unimported = []
    for page in DOCS.rglob("*.md"):
        text = " ".join(page.read_text().split())  # an import may wrap across lines
        for name in set(re.findall(r"`([a-z_]\w*)\(", text)) & set(homes):
            if not re.search(rf"from contextrl\.{homes[name]}[\w.]* import [^`]*\b{name}\b", text):
                unimported.append(f"{page.name}: {name} (contextrl.{homes[name]})")
    assert not unimported, unimported
