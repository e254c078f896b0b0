"""FMI 3.0 co-simulation FMUs in the master, alone and mixed with FMI 2.0 ones (foreign FMUs of tests/foreign/)."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
from fmpy import simulate_fmu
from foreign_fmus import packed, with_plant

from ncfmu.cli import main
from ncfmu.cosim.ssp import Component, Connection, System
from ncfmu.errors import SystemDefinitionError
from ncfmu.project import OpenSystem, simulate


def test_an_fmi3_axis_runs_the_lathe_cycle_as_its_fmi2_build_does(foreign, project, tmp_path):
    three = simulate(str(packed(with_plant("lathe_taper", "PlantAxis3"), foreign, tmp_path / "3")))
    two = simulate(str(packed(with_plant("lathe_taper", "PlantAxis"), foreign, tmp_path / "2")))
    assert three["seq.done"][-1] and not three["seq.alarm"].any() and three["seq.pass_no"].max() == 4
    # the same C model behind either interface, the same steps: the same trajectory, bit for bit
    for name in ("x_axis.pos", "z_axis.pos", "x_axis.following_error", "seq.x_cmd"):
        assert np.array_equal(three[name], two[name]), name
    assert np.array_equal(three["x_axis.in_position"], two["x_axis.in_position"])


def test_float64_int32_boolean_and_string_pass_between_fmi2_and_fmi3(foreign, project, tmp_path):
    system = System("mixed", [Component("count", "Countdown", {"end_at": 30.0}),
                              Component("feed", "Feedthrough3", {"gain": 2.0, "label": "three"})],
                    [Connection("count", "minutes", "feed", "time_in"),
                     Connection("count", "counter", "feed", "int_in")], 3.0, 0.01)
    with OpenSystem(packed(system, foreign, tmp_path)) as opened:
        run = opened.run(start_values={"feed.bool_in": True})
        assert opened.slaves[1].get("label") == "three"
    assert run["feed.time_out"][-1] == pytest.approx(2 * 3.0)      # min -> s converted, times the gain
    assert run["feed.int_out"][-1] == 3 and run["feed.int_out"].dtype == np.int32
    assert run["feed.bool_out"].all()


def test_fmpy_and_the_master_agree_on_an_fmi3_fmu(foreign, project, tmp_path):
    system = System("one", [Component("feed", "Feedthrough3", {"gain": 1.5})], [], 1.0, 0.1)
    with OpenSystem(packed(system, foreign, tmp_path)) as opened:
        run = opened.run(start_values={"feed.length_in": 2.0, "feed.int_in": 7})
    reference = simulate_fmu(str(foreign["Feedthrough3"]), stop_time=1.0, output_interval=0.1,
                             start_values={"gain": 1.5, "length_in": 2.0, "int_in": 7})
    assert run["feed.length_out"][-1] == reference["length_out"][-1] == 3.0
    assert run["feed.int_out"][-1] == reference["int_out"][-1] == 7


def test_an_fmi3_fmu_that_asks_to_end_ends_the_run(foreign, project, tmp_path):
    system = System("clock3", [Component("count", "Countdown3", {"end_at": 9.0})], [], 20.0, 0.01)
    with OpenSystem(packed(system, foreign, tmp_path)) as opened:
        run = opened.run()
    assert run.end_time == pytest.approx(9.0) and run["count.counter"][-1] == 9
    assert run.ended_by.startswith("count asked to end the simulation at t = 9 s")


def _with_float32(source, target):
    with zipfile.ZipFile(source) as z, zipfile.ZipFile(target, "w") as out:
        for entry in z.infolist():
            data = z.read(entry)
            if entry.filename == "modelDescription.xml":
                data = data.replace(b'<Float64 name="length_out"', b'<Float32 name="length_out"')
            out.writestr(entry, data)
    return target


def test_what_the_master_cannot_run_is_refused_by_vars_as_by_run(foreign, project, tmp_path, capsys):
    fmus = {"Feedthrough3": _with_float32(foreign["Feedthrough3"], tmp_path / "Feedthrough3.fmu")}
    archive = packed(System("f32", [Component("feed", "Feedthrough3")], [], 1.0), fmus, tmp_path / "sys")
    with pytest.raises(SystemDefinitionError, match="variable length_out is an FMI 3.0 Float32: not supported"):
        OpenSystem(archive)
    for command in ("vars", "run"):
        assert main([command, str(archive), *(("--out", str(tmp_path / "out")) if command == "run" else ())]) == 2
        err = capsys.readouterr().err
        assert "variable length_out is an FMI 3.0 Float32: not supported" in err and err.count("\n") == 1


def test_vars_lists_an_fmi3_fmus_variables_with_units(foreign, project, tmp_path, capsys):
    system = System("one", [Component("feed", "Feedthrough3")], [], 1.0)
    assert main(["vars", str(packed(system, foreign, tmp_path))]) == 0
    rows = {line.split()[0]: line.split() for line in capsys.readouterr().out.splitlines()[2:]}
    assert rows["feed.time_in"][:4] == ["feed.time_in", "input", "Float64", "s"]
    assert rows["feed.int_in"][:3] == ["feed.int_in", "input", "Int32"]
    assert rows["feed.label"][3:5] == ["String", "feed"]
