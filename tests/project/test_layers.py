"""Layers point one way: a module imports only from the layers below its own (docs/architecture.md).

Read from the source (``ast``), not by importing, so an import hidden inside a function counts too.
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
    "machining": {"errors"},
    "systems": {"errors", "ports", "files", "controllers", "servo", "cosim", "checks", "catalogue", "machining"},
}
#: what nothing below the front end may import: the front end itself
FRONT = {"project", "cli", "batch", "serve", "plots", "docs", "pytest_plugin"}
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


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_imports_point_down(path):
    layer = _layer(path)
    layers = set(ALLOWED) | FRONT | {_layer(p) for p in _modules()}
    bad = []
    for line, target in _imports(path):
        if target in layers and target != layer:
            if layer in ALLOWED and target not in ALLOWED[layer]:
                bad.append(f"line {line}: {layer} imports {target}")
        elif target in FORBIDDEN_PACKAGES.get(layer, ()):
            bad.append(f"line {line}: {layer} imports {target}")
    assert not bad, f"{path.relative_to(SRC)}: " + "; ".join(bad)


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
    "fmi2_model.h": {"fmi2_machine.h"},
    "fmi2_functions.c": {"fmi2_machine.h", "fmi2_model.h"},
    "fmi3_functions.c": {"fmi2_machine.h", "fmi2_model.h"},
    "native_model.c": {"fmi2_machine.h", "fmi2_model.h", "model_vars.h"},
    "python_model.c": {"fmi2_model.h", "ncfmu_contract.h"},
    "ncfmu_contract.h": set(),
    "model": {"fmi2_model.h", "model_vars.h"},        # + the model's own headers beside it
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
    assert _c_includes('#include <math.h>\n#include "fmi2_model.h"\n  # include "python_model.c"\n') == [
        "fmi2_model.h", "python_model.c"]
    assert "python_model.c" not in C_INCLUDES["model"] and "ncfmu_contract.h" not in C_INCLUDES["fmi2_functions.c"]
