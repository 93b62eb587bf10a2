"""Prints the import graph of src/contextrl, read statically with ast, and lists its import cycles, so
the dependency order between modules can be checked without importing anything.

    python tools/import_graph.py              # every edge; imports inside a function marked (deferred)
    python tools/import_graph.py --cycles     # only the cycles, with and without deferred imports

An import inside a function runs when the function is called, not when the module loads; it is an edge
of the graph all the same (the two modules still depend on each other), so cycles are listed twice: over
every import, and over module-level imports only (those are what break `import` itself).
tests/repository/test_layers.py uses `read_imports` and `cycles`.
"""

from __future__ import annotations

import argparse
import ast
from pathlib import Path
from typing import NamedTuple

SRC = Path(__file__).resolve().parent.parent / "src"


class Import(NamedTuple):
    """One import of a contextrl module by another: where it is written and whether it is deferred."""

    importer: str
    imported: str
    line: int
    deferred: bool  # written inside a function body: runs when called, not at module load


def module_names(src: Path = SRC) -> dict[str, Path]:
    """Dotted name of every module under src/contextrl (a package is named by its __init__.py)."""
    names = {}
    for path in sorted((src / "contextrl").rglob("*.py")):
        parts = path.relative_to(src).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        names[".".join(parts)] = path
    return names


def _statements(tree: ast.Module):
    """Yields (import statement, deferred) for every import in the tree, deferred when inside a function."""

    def walk(node: ast.AST, deferred: bool):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.Import | ast.ImportFrom):
                yield child, deferred
            inside = isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda)
            yield from walk(child, deferred or inside)

    yield from walk(tree, False)


def _targets(
    node: ast.Import | ast.ImportFrom, importer: str, is_package: bool, modules
) -> set[str]:
    """The contextrl modules one import statement names: a submodule when `from P import name` names one,
    else the package or module itself."""
    if isinstance(node, ast.Import):
        return {alias.name for alias in node.names if alias.name in modules}
    base = node.module or ""
    if node.level:
        package = importer.split(".") if is_package else importer.split(".")[:-1]
        package = package[: len(package) - (node.level - 1)]
        base = ".".join(package + ([base] if base else []))
    found = set()
    for alias in node.names:
        if f"{base}.{alias.name}" in modules:
            found.add(f"{base}.{alias.name}")
        elif base in modules:
            found.add(base)
    return found


def read_imports(src: Path = SRC) -> list[Import]:
    """Every import of one contextrl module by another, in file and line order."""
    modules = module_names(src)
    edges = []
    for importer, path in modules.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        is_package = path.name == "__init__.py"
        for node, deferred in _statements(tree):
            for imported in sorted(_targets(node, importer, is_package, modules)):
                if imported != importer:
                    edges.append(Import(importer, imported, node.lineno, deferred))
    return sorted(edges, key=lambda edge: (edge.importer, edge.line, edge.imported))


def cycles(edges: list[Import], include_deferred: bool = True) -> list[list[str]]:
    """The import cycles: each strongly connected group of two or more modules, its names sorted."""
    graph: dict[str, set[str]] = {}
    for edge in edges:
        if include_deferred or not edge.deferred:
            graph.setdefault(edge.importer, set()).add(edge.imported)
            graph.setdefault(edge.imported, set())
    # Tarjan's algorithm, iterative so a deep graph cannot hit the recursion limit.
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, successors = work[-1]
            for successor in successors:
                if successor not in index:
                    index[successor] = low[successor] = len(index)
                    stack.append(successor)
                    on_stack.add(successor)
                    work.append((successor, iter(sorted(graph[successor]))))
                    break
                if successor in on_stack:
                    low[node] = min(low[node], index[successor])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    group = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        group.append(member)
                        if member == node:
                            break
                    if len(group) > 1:
                        groups.append(sorted(group))
    return sorted(groups)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cycles", action="store_true", help="print only the cycles")
    args = parser.parse_args()
    edges = read_imports()
    if not args.cycles:
        for edge in edges:
            mark = "  (deferred)" if edge.deferred else ""
            print(f"{edge.importer} -> {edge.imported}  line {edge.line}{mark}")
        print()
    for title, include_deferred in (("all imports", True), ("module-level imports", False)):
        found = cycles(edges, include_deferred)
        print(f"cycles over {title}: {len(found)}")
        for group in found:
            print("  " + " <-> ".join(group))


if __name__ == "__main__":
    main()
