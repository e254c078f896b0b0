"""Value references are API: hosts, SSP tools and users' scripts address variables by number.

``value_references.json`` holds every model's variables and their value references as released; a variable may
be added (at the end), none may move or disappear. Read from the built FMUs' modelDescriptions.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from fmpy import read_model_description

STORED = json.loads(Path(__file__).with_name("value_references.json").read_text())


@pytest.mark.parametrize("model", sorted(STORED))
def test_no_variable_moves(model, fmus):
    now = {v.name: v.valueReference for v in read_model_description(str(fmus[model])).modelVariables}
    moved = {name: (vr, now.get(name)) for name, vr in STORED[model].items() if now.get(name) != vr}
    assert not moved, f"{model}: value references changed (was, now): {dict(list(moved.items())[:5])}"
    assert max(now.values()) + 1 == len(now), f"{model}: value references are not 0..{len(now) - 1}"
