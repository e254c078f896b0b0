"""The ``ncfmu.serving`` package: split by concern with its imports pointing one way (the simulation thread knows
nothing of OPC UA), and ``ncfmu.serve(...)`` callable whether or not the package was imported."""

from __future__ import annotations

import ast

import pytest
from conftest import ROOT

from ncfmu.errors import ConfigError

PACKAGE = ROOT / "src" / "ncfmu" / "serving"

#: module -> the package's modules it may import: each only those above it; the server all of them.
BELOW: dict[str, set[str]] = {
    "address_space": set(),
    "recording": set(),
    "security": set(),
    "crash_watch": set(),
    "runner": {"address_space", "recording", "crash_watch"},
    "cnc_model": {"address_space"},
    "server": {"address_space", "recording", "security", "crash_watch", "runner", "cnc_model"},
    "__init__": {"address_space", "recording", "security", "crash_watch", "runner", "cnc_model", "server"},
}
#: what only the OPC UA side may import
OPC_UA_ONLY = {"address_space", "recording", "crash_watch", "runner"}


def _imports(module: str) -> tuple[set[str], set[str]]:
    """(the package's modules, the third-party top-level packages) ``module`` imports, also inside functions."""
    ours, theirs = set(), set()
    for node in ast.walk(ast.parse((PACKAGE / f"{module}.py").read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            ours |= {node.module} if node.module else {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            theirs.add(node.module.split(".")[0])
        elif isinstance(node, ast.Import):
            theirs |= {a.name.split(".")[0] for a in node.names}
    return ours, theirs


def test_every_module_of_the_package_is_placed():
    assert {p.stem for p in PACKAGE.glob("*.py")} == set(BELOW)


@pytest.mark.parametrize("module", sorted(BELOW))
def test_the_package_imports_point_one_way(module):
    ours, theirs = _imports(module)
    assert ours <= BELOW[module], f"serving/{module}.py imports {sorted(ours - BELOW[module])}"
    if module in OPC_UA_ONLY:
        assert "asyncua" not in theirs, f"serving/{module}.py imports asyncua"


def test_ncfmu_serve_stays_callable_once_the_package_is_imported():
    """README: ``ncfmu.serve("grinder_feed", ...)`` from Python scripts. The package is ``ncfmu.serving`` so that
    importing it never binds the name ``ncfmu.serve`` over ncfmu's function: the call still reaches
    :func:`ncfmu.serving.serve` (here its first check, the endpoint's, refuses before anything is opened)."""
    import ncfmu
    import ncfmu.serving.runner  # noqa: F401  (a package named serve would bind ncfmu.serve here)
    with pytest.raises(ConfigError) as refused:
        ncfmu.serve("lathe_taper", endpoint="http://127.0.0.1:4840/ncfmu")
    assert str(refused.value) == "--endpoint = 'http://127.0.0.1:4840/ncfmu': must be opc.tcp://HOST:PORT/PATH"
