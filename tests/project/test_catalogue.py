"""One registry of models: the catalogue finds every model in the code; everything else asks it."""

from __future__ import annotations

import shutil

import pytest
from conftest import ROOT

from ncfmu import catalogue
from ncfmu.controllers.base import Controller
from ncfmu.errors import BuildError
from ncfmu.fmi.builder import model_scripts
from ncfmu.fmi.native import native_models
from ncfmu.systems import MODELS


def test_the_catalogue_is_every_model_and_the_rest_derives_from_it():
    found = catalogue.models()
    assert list(found) == ["AreaLimiter", "ContourInterpolator", "CutSequencer", "OperatorPanel", "ProgrammableFeed",
                           "ServoAxis", "SpindleDrive"]
    assert MODELS == found                                              # the systems' component checks
    assert [m.name for m in native_models()] == catalogue.native_models() == ["ServoAxis", "SpindleDrive"]
    assert [p.stem for p in model_scripts(ROOT / "models")] == catalogue.python_models()
    assert sorted(p.stem for p in (ROOT / "docs" / "fmus").glob("*.md")) == list(found)


def test_a_test_s_own_controller_is_not_a_model():
    class Fake(Controller):
        MODEL_NAME = "Fake"
    catalogue.models.cache_clear()
    try:
        assert "Fake" not in catalogue.models()
    finally:
        catalogue.models.cache_clear()


def test_the_builder_names_a_model_without_its_script_and_a_script_of_no_model(tmp_path):
    scripts = tmp_path / "models"
    shutil.copytree(ROOT / "models", scripts)
    (scripts / "OperatorPanel.py").unlink()
    with pytest.raises(BuildError, match="no model script for OperatorPanel"):
        model_scripts(scripts)
    shutil.copy(ROOT / "models" / "OperatorPanel.py", scripts / "OperatorPanel.py")
    (scripts / "Lathe2.py").write_text("")
    with pytest.raises(BuildError, match="Lathe2.py names no controller"):
        model_scripts(scripts)
