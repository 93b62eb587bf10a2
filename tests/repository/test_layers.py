"""The import graph of src/contextrl reads in one direction: no cycles, and no module-level import runs
up a layer of docs/architecture.md's table (data flows down, nothing imports upward).

The graph is read statically (tools/import_graph.py), so these tests import none of the modules.
"""

import importlib.util
import re

import pytest

from tests.helpers import ROOT

pytestmark = pytest.mark.quick

_spec = importlib.util.spec_from_file_location("import_graph", ROOT / "tools" / "import_graph.py")
import_graph = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(import_graph)

# The layers of docs/architecture.md, lowest first, as package prefixes. A module may import its own layer and those
# below it. ``contextrl`` is the package itself (matched exactly): it registers the environments and
# their gymnasium ids, so it sits with the faces. render draws the families' states (the box2d family
# draws on its canvas), so it sits beside envs; testing is the env checker users run on their own envs.
LAYERS = [
    (
        "core + context",
        [
            "contextrl.core",
            "contextrl.context",
            "contextrl.xla_flags",
            "contextrl.compile_cache",
            "contextrl.testing",
        ],
    ),
    ("envs", ["contextrl.envs", "contextrl.render"]),
    (
        "gymnasium",
        [
            "contextrl.gymnasium",
            "contextrl.carl",
            "contextrl.gymnax",
            "contextrl.torch",
            "contextrl",
        ],
    ),
    ("agents", ["contextrl.agents"]),
    ("analysis", ["contextrl.analysis"]),
    ("experiments", ["contextrl.experiments"]),
    ("paper", ["contextrl.paper"]),
    ("cli", ["contextrl.cli", "contextrl.__main__", "contextrl.demo"]),
]

# Inside experiments, the order the modules build on each other (lowest first): specs, the protocol
# record, their expansion into a plan of trials, running a chunk, run directories and more seeds for
# one (starting Ray, and where Ray's output goes in a run), reports, the protocols, executors, a
# run's preview and its TensorBoard log, the runner, the commands around it, and the package. The protocols live in their own folder,
# protocols/, whose package registers them.
EXPERIMENTS = [
    "spec",
    "protocol",
    "plan",
    "trials",
    "runs",
    "more_seeds",
    "ray_cluster",
    "ray_output",
    "reports",
    "protocols.sensitivity",
    "protocols.optimality_gap",
    "protocols.visibility",
    "protocols.train_test",
    "protocols.tabular",
    "protocols.hpo",
    "protocols.curriculum",
    "protocols",
    "executors",
    "planning",
    "tensorboard",
    "runner",
    "reevaluate",
    "compare",
    "commands",
]


def layer_of(module: str) -> int:
    """Index in LAYERS of the longest prefix naming ``module``."""
    best, depth = None, -1
    for index, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            exact = prefix == "contextrl"
            if module == prefix or (not exact and module.startswith(prefix + ".")):
                if len(prefix) > depth:
                    best, depth = index, len(prefix)
    if best is None:
        raise AssertionError(f"{module} is in no layer; add its package to LAYERS in {__file__}")
    return best


def experiments_rank(module: str) -> int:
    """Position of an experiments module in EXPERIMENTS (the package itself comes last)."""
    name = module.removeprefix("contextrl.experiments").lstrip(".")
    if not name:
        return len(EXPERIMENTS)
    if name not in EXPERIMENTS:
        raise AssertionError(f"{module} is not placed; add it to EXPERIMENTS in {__file__}")
    return EXPERIMENTS.index(name)


@pytest.fixture(scope="module")
def edges():
    return import_graph.read_imports()


def test_no_import_cycles(edges):
    """Neither module-level imports nor imports deferred into functions close a circle."""
    assert import_graph.cycles(edges, include_deferred=False) == []
    assert import_graph.cycles(edges, include_deferred=True) == []


def test_every_module_has_a_layer(edges):
    modules = import_graph.module_names()
    assert modules, "found no modules under src/contextrl"
    for module in modules:
        layer_of(module)


def test_no_module_level_import_runs_up_a_layer(edges):
    upward = [
        f"{edge.importer} (line {edge.line}, {LAYERS[layer_of(edge.importer)][0]}) imports "
        f"{edge.imported} ({LAYERS[layer_of(edge.imported)][0]})"
        for edge in edges
        if not edge.deferred and layer_of(edge.imported) > layer_of(edge.importer)
    ]
    assert upward == []


def test_experiments_import_in_their_order(edges):
    """spec → protocol → plan → trials → runs → … → executors → runner → commands: a module imports only
    those before it, so each file's header shows what it builds on."""
    backward = [
        f"{edge.importer} (line {edge.line}) imports {edge.imported}"
        for edge in edges
        if edge.importer.startswith("contextrl.experiments")
        and edge.imported.startswith("contextrl.experiments")
        and experiments_rank(edge.imported) >= experiments_rank(edge.importer)
    ]
    assert backward == []


def test_the_checker_finds_a_cycle(tmp_path):
    """The checker itself: a two-module circle through a deferred import is found, and only when
    deferred imports count."""
    package = tmp_path / "contextrl"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("from contextrl import b\n")
    (package / "b.py").write_text("def f():\n    from contextrl.a import g\n")
    edges = import_graph.read_imports(tmp_path)
    assert [(e.importer, e.imported, e.deferred) for e in edges] == [
        ("contextrl.a", "contextrl.b", False),
        ("contextrl.b", "contextrl.a", True),
    ]
    assert import_graph.cycles(edges) == [["contextrl.a", "contextrl.b"]]
    assert import_graph.cycles(edges, include_deferred=False) == []


def test_the_architecture_page_shows_these_layers():
    """docs/architecture.md's table lists the layers top down with exactly the packages above."""
    page = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    rows = [line.split("|")[1:3] for line in page.splitlines() if line.startswith("| ")][2:]
    shown = [(name.strip(), re.findall(r"`([\w.]+)`", packages)) for name, packages in rows]
    assert shown == [(name, prefixes) for name, prefixes in reversed(LAYERS)]
