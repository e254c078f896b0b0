"""A Python FMU claims only what it carries: one binary, the shim built and tested here (linux64), no other
platform's library without the shim; needsExecutionTool is false (the binary loads the Python runtime itself);
its documentation says what it needs at run time."""

from __future__ import annotations

import re
import sys
import zipfile

import pytest

PYTHON_FMUS = ["AreaLimiter", "ContourInterpolator", "CutSequencer", "OperatorPanel", "ProgrammableFeed"]


@pytest.mark.parametrize("model", PYTHON_FMUS)
def test_only_the_shim_binary_is_listed_and_the_runtime_is_documented(fmus, model):
    with zipfile.ZipFile(fmus[model]) as z:
        names = z.namelist()
        description = z.read("modelDescription.xml").decode()
        doc = z.read("documentation/index.html").decode()
        binary = z.read(f"binaries/linux64/{model}.so")
    assert [n for n in names if n.startswith("binaries/")] == [f"binaries/linux64/{model}.so"]
    assert b"fmi_take_log" in binary                    # the shim, driving the adapter through the contract
    assert re.search(r'<CoSimulation [^>]*needsExecutionTool="false"', description)
    version = ".".join(map(str, sys.version_info[:2]))
    assert f"CPython it was built with, {version}" in doc
    assert "NCFMU_LIBPYTHON" in doc and "resources/ncfmu_python.txt" in doc and "linux64" in doc
