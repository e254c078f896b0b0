"""A component is what its modelDescription says, never its file name; the report finds axes by their role."""

from __future__ import annotations

import re

import pytest
from foreign_fmus import packed, with_plant

from ncfmu.cli import main
from ncfmu.project import OpenSystem
from ncfmu.systems import report_for
from ncfmu.systems.roles import axes


def test_a_foreign_fmu_packed_under_our_models_name_is_known_by_its_model_description(foreign, project, tmp_path,
                                                                                      capsys):
    system = with_plant("lathe_taper", "ServoAxis")          # the file is resources/ServoAxis.fmu ...
    archive = packed(system, {"ServoAxis": foreign["PlantAxis"]}, tmp_path)   # ... its content the foreign plant
    assert main(["vars", str(archive), "--instance", "x_axis"]) == 0
    listing = capsys.readouterr().out
    names = [line.split()[0] for line in listing.splitlines()[2:]
             if not line.startswith("  ") and line.split()[1] != "output"]
    assert re.search(r"  foreign FMU x_axis: PlantAxis \(foreign: GUID \{[0-9a-f-]+\}, hand-written C", listing)
    assert names == [f"x_axis.{v}" for v in ("pos_cmd", "vel_ff", "Kv", "tau_vel", "vel_max", "inpos_band",
                                             "pos_start")]
    with OpenSystem(archive) as opened:
        identity = opened.identities["x_axis"]
        assert identity.model == "" and identity.model_name == "PlantAxis"
        assert "hand-written C" in identity.generation_tool
        assert opened.identities["seq"].model == "CutSequencer"
    assert main(["run", str(archive), "--set", "x_axis.kaff=0.5", "--out", str(tmp_path / "out")]) == 2
    assert "x_axis has no variable 'kaff'" in capsys.readouterr().err


def test_axes_are_found_by_their_role(foreign, project, tmp_path):
    system = with_plant("lathe_taper", "PlantAxis")
    with OpenSystem(packed(system, foreign, tmp_path)) as opened:
        models = opened.models
    assert models["x_axis"] == "foreign:PlantAxis" and models["limiter"] == "AreaLimiter"
    assert axes(system, models) == ["x_axis", "z_axis"]
    assert report_for("lathe_taper", models) is report_for("lathe_taper")


def test_run_with_a_foreign_axis_gives_the_full_summary_and_a_plot_with_its_following_error(foreign, project,
                                                                                          tmp_path, capsys):
    archive = packed(with_plant("lathe_taper", "PlantAxis"), foreign, tmp_path)
    assert main(["run", str(archive), "--out", str(tmp_path / "out"), "--plot"]) == 0
    out = capsys.readouterr().out
    assert "  cuts (SC2): 4" in out and re.search(r"cycle done: 4\d\.\d+ s; .* alarm: no", out)
    assert re.search(r"  x_axis: max \|following error\| \d+\.\d+ um", out)
    assert (tmp_path / "out" / "lathe_taper.png").stat().st_size > 10_000


@pytest.mark.parametrize("model", ["PlantAxis"])
def test_a_sweep_calls_an_unfinished_cycle_with_a_foreign_axis_unfinished(foreign, project, tmp_path, model):
    from ncfmu.batch import sweep
    archive = packed(with_plant("lathe_taper", model), foreign, tmp_path)
    rows = sweep(str(archive), {"seq.block[1].N": [4]}, tmp_path / "sweep", workers=0, stop_time=10.0)
    assert [r["status"] for r in rows] == ["unfinished"]


def test_a_users_own_system_reports_its_axes_found_by_role(foreign, project, tmp_path, capsys):
    # lathe_taper renamed, its axes named otherwise and foreign: the generic report finds them by what they feed
    system = with_plant("lathe_taper", "PlantAxis")
    system.name = "my_lathe"
    for comp in system.components:
        if comp.name.endswith("_axis"):
            old = comp.name
            comp.name = {"x_axis": "cross_slide", "z_axis": "carriage"}[old]
            for c in system.connections:
                c.start_element = comp.name if c.start_element == old else c.start_element
                c.end_element = comp.name if c.end_element == old else c.end_element
    assert main(["run", str(packed(system, foreign, tmp_path)), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert re.search(r"  cross_slide: max \|following error\| \d+\.\d+ um", out)
    assert re.search(r"  carriage: max \|following error\| \d+\.\d+ um", out)
