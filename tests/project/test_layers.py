"""Layers point one way: a module imports only from the layers below its own (docs/architecture.md).

Every module of the package, down to the package root, belongs to a layer: the layers below the front end
(:data:`ALLOWED`) or the front end (:data:`FRONT`); the C sources too (:data:`C_INCLUDES`). Read from the source
(``ast``, the ``#include`` lines), not by importing, so an import hidden inside a function counts too.
"""

from __future__ import annotations

import ast
import re

import pytest
from conftest import ROOT

SRC = ROOT / "src" / "ncfmu"

#: layer -> the ncfmu layers it may import (besides itself). Top-level modules are their own layer.
ALLOWED: dict[str, set[str]] = {
    "errors": set(),
    "files": set(),
    "ports": {"errors"},
    "controllers": {"errors", "ports"},
    "servo": {"errors", "ports", "controllers"},
    "catalogue": {"errors", "ports", "controllers", "servo"},
    "fmi": {"errors", "ports", "files", "controllers", "servo", "catalogue"},
    "cosim": {"errors", "ports", "files"},
    "checks": {"errors", "ports", "controllers", "cosim"},
    "systems": {"errors", "ports", "files", "controllers", "servo", "cosim", "checks", "catalogue"},
}
#: The front end: what nothing below it may import. Each front module may import every layer of ALLOWED and the
#: front modules named here (``__init__`` is the package root: ``ncfmu.serve``).
FRONT: dict[str, set[str]] = {
    "docs": set(),
    "plots": set(),
    "project": {"docs"},
    "batch": {"project"},
    "serving": {"project"},
    "pytest_plugin": {"project"},
    "cli": {"project", "batch", "serving", "plots"},
    "__init__": {"serving"},
}
#: The C sources by folder (relative to the package): the quoted headers each may include besides its own folder's.
#: The FMI layer includes the standard's headers (from fmpy) and a model's generated variables; a native model
#: includes only the model interface (fmi/c/fmi2_model.h) and its variables; the master's loop includes nothing.
C_INCLUDES: dict[str, set[str]] = {
    "fmi/c": {"fmi2Functions.h", "model_vars.h"},
    "servo/native": {"fmi2_model.h", "model_vars.h"},
    "cosim": set(),
}
#: third-party packages a layer must not import (the controllers run inside FMUs on the standard library)
FORBIDDEN_PACKAGES = {"controllers": {"pythonfmu", "fmpy", "numpy", "scipy", "control"},
                      "cosim": {"pythonfmu"}}


def _layer(path) -> str:
    rel = path.relative_to(SRC)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def _imports(path) -> list[tuple[int, str]]:
    """(line, imported ncfmu layer or third-party top-level package) of every import in ``path``."""
    return _imports_in(path.read_text(), path.relative_to(SRC.parent).with_suffix("").parts[:-1])


def _imports_in(source: str, package: tuple[str, ...]) -> list[tuple[int, str]]:
    """The imports of ``source``, a module of ``package`` (e.g. ``("ncfmu", "cosim")``)."""
    tree = ast.parse(source)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                found.append((node.lineno, parts[1] if parts[0] == "ncfmu" and len(parts) > 1 else parts[0]))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = list(package[:len(package) - node.level + 1])
                parts = base + (node.module.split(".") if node.module else [])
                if len(parts) == 1:            # "from .. import x": x names the layer
                    found += [(node.lineno, alias.name) for alias in node.names]
                else:
                    found.append((node.lineno, parts[1]))
            elif node.module:
                parts = node.module.split(".")
                found.append((node.lineno, parts[1] if parts[0] == "ncfmu" and len(parts) > 1 else parts[0]))
    return found


def _modules():
    return sorted(p for p in SRC.rglob("*.py") if "__pycache__" not in p.parts)


def _layers() -> set[str]:
    return {_layer(p) for p in _modules()}


def test_every_module_has_a_layer():
    """Down to the package root: a module (or package) in neither ALLOWED nor FRONT is unplaced; a name in
    FRONT that is no module (a misspelling) checks nothing."""
    layers, placed = _layers(), set(ALLOWED) | set(FRONT)
    assert not layers - placed, f"modules without a layer: {sorted(layers - placed)}"
    assert not placed - layers, f"layers naming no module: {sorted(placed - layers)}"
    assert not set(ALLOWED) & set(FRONT)


def _violations(layer: str, imports: list[tuple[int, str]], layers: set[str]) -> list[str]:
    bad = []
    for line, target in imports:
        if target in layers and target != layer:
            if layer in ALLOWED and target not in ALLOWED[layer]:
                bad.append(f"line {line}: {layer} imports {target}")
            elif layer in FRONT and target in FRONT and target not in FRONT[layer]:
                bad.append(f"line {line}: {layer} imports the front-end module {target}")
        elif target in FORBIDDEN_PACKAGES.get(layer, ()):
            bad.append(f"line {line}: {layer} imports {target}")
    return bad


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_imports_point_down(path):
    bad = _violations(_layer(path), _imports(path), _layers())
    assert not bad, f"{path.relative_to(SRC)}: " + "; ".join(bad)


def test_the_front_end_rule_catches_a_front_import():
    """The check itself: a layer below the front end importing a front module, and a front module importing a front
    module it is not given, are found; front to a lower layer is fine."""
    layers = _layers()
    assert _violations("cosim", [(3, "project")], layers) == ["line 3: cosim imports project"]
    assert _violations("serving", [(5, "cli"), (6, "project"), (7, "cosim")], layers) == [
        "line 5: serving imports the front-end module cli"]


def _c_sources():
    return sorted(p for p in SRC.rglob("*") if p.suffix in (".c", ".h"))


def _includes(text: str) -> list[tuple[int, str]]:
    return [(n, m.group(1)) for n, line in enumerate(text.splitlines(), start=1)
            if (m := re.match(r'\s*#\s*include\s+"([^"]+)"', line))]


@pytest.mark.parametrize("path", _c_sources(), ids=lambda p: str(p.relative_to(SRC)))
def test_c_includes_point_down(path):
    folder = path.parent.relative_to(SRC).as_posix()
    assert folder in C_INCLUDES, f"{path.relative_to(SRC)}: C in a folder without a layer ({folder})"
    own = {p.name for p in path.parent.iterdir()}
    bad = [f"line {n}: includes {h!r}" for n, h in _includes(path.read_text())
           if h not in own and h not in C_INCLUDES[folder]]
    assert not bad, f"{path.relative_to(SRC)}: " + "; ".join(bad)


def test_the_c_rule_catches_an_upward_include():
    assert [h for _, h in _includes('#include <math.h>\n#include "fmi2_machine.h"\n  # include "x.h"\n')] == [
        "fmi2_machine.h", "x.h"]
    assert "fmi2_machine.h" not in C_INCLUDES["servo/native"]        # a native model sees the interface only


def test_the_rule_catches_an_upward_import():
    """The check itself: upward imports, also inside a function and relative ones, are found."""
    source = "import numpy\nfrom ..errors import ConfigError\ndef f():\n    from ..project import simulate\n"
    assert [t for _, t in _imports_in(source, ("ncfmu", "cosim"))] == ["numpy", "errors", "project"]
    assert [t for _, t in _imports_in("from . import master\nimport ncfmu.cli\n", ("ncfmu", "cosim"))] == [
        "cosim", "cli"]
