"""No import cycles between the package's modules, deferred ones included: an import inside a function, or under
``if TYPE_CHECKING``, is an edge of the graph as a top-level one is (read from the source with ``ast``, as
test_layers.py reads the layers, not by importing)."""

from __future__ import annotations

import ast

from conftest import ROOT

SRC = ROOT / "src" / "ncfmu"


def _modules() -> dict[str, tuple[str, bool]]:
    """Dotted name -> (source, is a package's ``__init__``) of every module of the package."""
    found = {}
    for path in sorted(SRC.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        rel = path.relative_to(SRC.parent).with_suffix("")
        package = rel.name == "__init__"
        found[".".join(rel.parts[:-1] if package else rel.parts)] = (path.read_text(), package)
    return found


def import_graph(modules: dict[str, tuple[str, bool]]) -> dict[str, set[str]]:
    """Module -> the package's modules it imports. ``from pkg import sub`` of a submodule is an edge to ``pkg.sub``
    only (Python has made ``pkg`` before any of its submodules); of any other name, to ``pkg``."""
    def owner(name: str) -> str:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name

    graph: dict[str, set[str]] = {m: set() for m in modules}
    for module, (source, package) in modules.items():
        here = module if package else module.rpartition(".")[0]
        for node in ast.walk(ast.parse(source)):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here.split(".")[:len(here.split(".")) - node.level + 1]
                    origin = ".".join(base + (node.module.split(".") if node.module else []))
                else:
                    origin = node.module or ""
                names = [f"{origin}.{alias.name}" for alias in node.names]
                targets = [n if n in modules else origin for n in names]
            graph[module] |= {t for t in map(owner, targets) if t and t != module}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_package_has_no_import_cycle():
    graph = import_graph(_modules())
    found = cycles(graph)
    described = ["; ".join(f"{a} -> {b}" for a in c for b in sorted(graph[a] & set(c))) for c in found]
    assert not found, "import cycles: " + " | ".join(described)


def test_the_check_finds_deferred_and_type_only_cycles():
    """The check itself: a cycle closed by an import inside a function, or under TYPE_CHECKING, is found; a
    submodule importing a sibling through its package (``from . import sibling``) is no edge to the package."""
    modules = {
        "p": ("from .a import A\n", True),
        "p.a": ("def f():\n    from .b import B\n", False),
        "p.b": ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .a import A\n", False),
        "p.c": ("from . import a\n", False),
        "p.d": ("from . import VERSION\n", False),
    }
    graph = import_graph(modules)
    assert graph["p.a"] == {"p.b"} and graph["p.b"] == {"p.a"} and graph["p.c"] == {"p.a"}
    assert graph["p.d"] == {"p"}
    assert cycles(graph) == [["p.a", "p.b"]]
