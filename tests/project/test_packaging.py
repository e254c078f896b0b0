"""The install a newcomer gets is the one CI tested: every package pinned once, in .ci/constraints.txt.

The README's two commands and .ci/run install with ``-c .ci/constraints.txt``; pyproject.toml names the
dependencies, and a runtime dependency's lower bound is the version CI installs (so the bound was tested).
"""

from __future__ import annotations

import re
import tomllib

from conftest import ROOT
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name


def _pins() -> dict[str, str]:
    pins = {}
    for line in (ROOT / ".ci" / "constraints.txt").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name, _, version = line.partition("==")
            assert version, f".ci/constraints.txt: {line!r} is not an exact pin NAME==VERSION"
            pins[canonicalize_name(name)] = version
    return pins


def _project() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def test_every_dependency_and_tool_is_pinned_exactly_once():
    pins = _pins()
    project = _project()
    names = [Requirement(r).name for r in project["dependencies"]]
    for extra in project["optional-dependencies"].values():
        names += [Requirement(r).name for r in extra]
    missing = sorted({n for n in names if canonicalize_name(n) not in pins})
    assert not missing, f"not pinned in .ci/constraints.txt: {missing}"
    for tool in ("pytest", "ruff", "mypy", "hypothesis"):
        assert tool in pins


def test_runtime_lower_bounds_are_the_tested_versions():
    pins = _pins()
    for raw in _project()["dependencies"]:
        req = Requirement(raw)
        lower = [s.version for s in req.specifier if s.operator == ">="]
        assert lower, f"{raw}: no lower bound"
        assert lower[0] == pins[canonicalize_name(req.name)], (
            f"{raw}: the lower bound is not the version CI tests ({pins[canonicalize_name(req.name)]})")


def test_readme_commands_install_with_the_constraints():
    readme = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```bash\n(.*?)\n```", readme, flags=re.S)[:2]
    assert len(blocks) == 2
    for command in blocks:
        assert command.startswith("pip install -c .ci/constraints.txt -e ")
    assert blocks[1].endswith("python -m pytest -q tests")
