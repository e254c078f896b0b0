"""Layers point one way: a module imports only from the layers below its own (docs/architecture.md).

Every module of the package, down to the package root, belongs to a layer: the layers below the front end
(:data:`ALLOWED`) or the front end (:data:`FRONT`); the C sources too (:data:`C_INCLUDES`, :data:`C_STANDALONE`).
Read from the source (``ast``, the ``#include`` lines), not by importing, so an import hidden inside a function
counts too.
"""

from __future__ import annotations

import ast
import re

import pytest
from conftest import ROOT

SRC = ROOT / "src" / "ncfmu"

#: layer -> the ncfmu layers it may import (besides itself). Top-level modules are their own layer.
ALLOWED: dict[str, set[str]] = {
    "version": set(),
    "errors": set(),
    "exitcodes": set(),
    "files": {"version"},
    "ports": {"errors"},
    "controllers": {"errors", "ports"},
    "servo": {"errors", "ports", "controllers"},
    "catalogue": {"errors", "ports", "controllers", "servo"},
    "fmi": {"version", "errors", "ports", "files", "controllers", "servo", "catalogue"},
    "cosim": {"errors", "ports", "files"},
    "checks": {"errors", "ports", "controllers", "cosim"},
    "machining": {"errors"},
    "systems": {"errors", "exitcodes", "ports", "files", "controllers", "servo", "cosim", "checks", "catalogue",
                "machining"},
}
#: The front end: what nothing below it may import. Each front module may import every layer of ALLOWED and the
#: front modules named here (``__init__`` is the package root: ``ncfmu.serving``).
FRONT: dict[str, set[str]] = {
    "docs": set(),
    "plots": set(),
    "project": {"docs"},
    "batch": {"project"},
    "serving": {"project"},
    "web": {"serving"},
    "pytest_plugin": {"project"},
    "cli": {"project", "batch", "serving", "web", "plots"},
    "__init__": {"serving"},
}
#: third-party packages a layer must not import (the controllers run inside FMUs on the standard library)
FORBIDDEN_PACKAGES = {"controllers": {"pythonfmu", "fmpy", "numpy", "scipy", "control", "shapely"},
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


#: C outside the FMI layers and the native models (whose includes are C_INCLUDES below): the master's loop, which
#: includes no project header at all.
C_STANDALONE = {"cosim/loop.c"}


def test_every_c_file_has_a_layer():
    """Down to the package root: a C source neither under the FMI layers' or the models' rule (C_FILES) nor standalone
    is unplaced; a standalone one includes no project header."""
    files = {p.relative_to(SRC).as_posix() for p in SRC.rglob("*.[ch]")}
    placed = {p.relative_to(SRC).as_posix() for p in C_FILES} | C_STANDALONE
    assert not files - placed, f"C sources without a layer: {sorted(files - placed)}"
    assert not C_STANDALONE - files, f"C_STANDALONE names no file: {sorted(C_STANDALONE - files)}"
    for name in C_STANDALONE:
        assert not _c_includes((SRC / name).read_text()), f"{name} includes a project header"


def test_the_rule_catches_an_upward_import():
    """The check itself: upward imports, also inside a function and relative ones, are found."""
    source = "import numpy\nfrom ..errors import ConfigError\ndef f():\n    from ..project import simulate\n"
    assert [t for _, t in _imports_in(source, ("ncfmu", "cosim"))] == ["numpy", "errors", "project"]
    assert [t for _, t in _imports_in("from . import master\nimport ncfmu.cli\n", ("ncfmu", "cosim"))] == [
        "cosim", "cli"]


# -- the C layers: the FMI layers stand over the model interface only; models never reach into a layer -------------
#: For each C file (by name, or "model" for a native model's own files under servo/native/), the project headers it
#: may include (system headers <...> and the FMI standard's headers, as fmpy ships them, always).
C_INCLUDES = {
    "fmi2_machine.h": set(),
    "model.h": {"fmi2_machine.h"},
    "fmu_instance.h": {"fmi2_machine.h", "model.h"},    # the FMI layers' instances and states, written once
    "fmi2_functions.c": {"fmi2_machine.h", "model.h", "fmu_instance.h"},
    "fmi3_functions.c": {"fmi2_machine.h", "model.h", "fmu_instance.h"},
    "native_model.c": {"fmi2_machine.h", "model.h", "model_vars.h"},
    "python_model.c": {"model.h", "ncfmu_contract.h"},
    "ncfmu_contract.h": set(),
    "model": {"model.h", "model_vars.h"},        # + the model's own headers beside it
}
FMI_STANDARD_HEADERS = {"fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h", "fmi3Functions.h",
                        "fmi3FunctionTypes.h", "fmi3PlatformTypes.h"}
C_FILES = sorted([*(SRC / "fmi" / "c").glob("*.[ch]"), *(SRC / "servo" / "native").glob("*.[ch]")])


def _c_includes(text: str) -> list[str]:
    return re.findall(r'^\s*#\s*include\s+"([^"]+)"', text, re.MULTILINE)


@pytest.mark.parametrize("path", C_FILES, ids=lambda p: str(p.relative_to(SRC)))
def test_c_includes_follow_the_layers(path):
    own = {p.name for p in path.parent.glob("*.h")} if path.parent.name == "native" else set()
    allowed = (C_INCLUDES["model"] | own) if path.parent.name == "native" else C_INCLUDES[path.name]
    bad = [h for h in _c_includes(path.read_text()) if h not in allowed | FMI_STANDARD_HEADERS]
    assert not bad, f"{path.relative_to(SRC)} includes {bad}: allowed {sorted(allowed)}"


def test_the_c_rule_catches_a_model_reaching_into_a_layer():
    assert _c_includes('#include <math.h>\n#include "model.h"\n  # include "python_model.c"\n') == [
        "model.h", "python_model.c"]
    assert "python_model.c" not in C_INCLUDES["model"] and "ncfmu_contract.h" not in C_INCLUDES["fmi2_functions.c"]
