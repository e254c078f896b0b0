"""Units as SSP 1.0 defines them: conversions between connected FMUs, refusals, warnings; connectors checked."""

from __future__ import annotations

import numpy as np
import pytest
from foreign_fmus import packed, with_plant

from ncfmu.cosim.ssp import Component, Connection, System
from ncfmu.cosim.units import Unit, conversion
from ncfmu.errors import SystemDefinitionError
from ncfmu.project import OpenSystem, simulate

MM = Unit.of("mm", {"m": 1}, 1e-3)
M = Unit.of("m", {"m": 1})
S = Unit.of("s", {"s": 1})
MIN = Unit.of("min", {"s": 1}, 60)
DEGC = Unit.of("degC", {"K": 1}, 1, 273.15)
DEGF = Unit.of("degF", {"K": 1}, 5 / 9, 273.15 - 32 * 5 / 9)


def test_conversions_follow_the_si_exponents_factor_and_offset():
    assert conversion(MM, M).gain == pytest.approx(1e-3) and conversion(M, MM).gain == pytest.approx(1e3)
    assert conversion(MIN, S).gain == 60 and conversion(MIN, S).offset == 0
    to_f = conversion(DEGC, DEGF)
    assert to_f.gain * 100 + to_f.offset == pytest.approx(212.0)
    assert conversion(MM, S) is None
    assert conversion(Unit("furlong"), Unit("furlong")).identity and conversion(Unit("a"), Unit("b")) is None


def test_a_plant_in_metres_runs_the_lathe_cycle_through_converted_connections(foreign, project, tmp_path):
    metre = simulate(str(packed(with_plant("lathe_taper", "PlantAxisMetre", 1e-3), foreign, tmp_path / "m")))
    mm = simulate(str(packed(with_plant("lathe_taper", "PlantAxis"), foreign, tmp_path / "mm")))
    for run in (metre, mm):
        assert run["seq.done"][-1] and not run["seq.alarm"].any() and run["seq.pass_no"].max() == 4
    # the same plant in other units: the same cycle, positions 1000 times smaller in m
    assert metre["x_axis.pos"] * 1e3 == pytest.approx(mm["x_axis.pos"], abs=1e-9)
    assert np.abs(metre["seq.x_cmd"] - mm["seq.x_cmd"]).max() < 1e-9


def test_a_connection_between_different_quantities_is_refused_naming_both_ends(foreign, project, tmp_path):
    system = System("mixed", [Component("plant", "PlantAxis"), Component("feed", "Feedthrough")],
                    [Connection("plant", "pos", "feed", "time_in")], 1.0)
    with pytest.raises(SystemDefinitionError, match=r"plant\.pos is in mm \(m\), feed\.time_in in s \(s\): not the "
                                                    "same quantity"):
        OpenSystem(packed(system, foreign, tmp_path))


def test_minutes_convert_to_seconds_through_a_declared_type(foreign, project, tmp_path):
    system = System("clock", [Component("count", "Countdown", {"end_at": 30.0}), Component("feed", "Feedthrough")],
                    [Connection("count", "minutes", "feed", "time_in")], 5.0, 0.01)
    with OpenSystem(packed(system, foreign, tmp_path)) as opened:
        assert opened.slaves[1].variables["time_in"].unit == "s"      # from the declaredType "Time"
        run = opened.run()
    assert run["count.minutes"][-1] == pytest.approx(5.0 / 60)
    assert run["feed.time_out"][-1] == pytest.approx(5.0)    # Gauss-Seidel: this step's minutes, in s


def test_a_connection_with_a_side_without_unit_is_warned(foreign, project, tmp_path):
    run = simulate(str(packed(with_plant("lathe_taper", "PlantAxisBare"), foreign, tmp_path)))
    assert "connection limiter.lim_cmd -> x_axis.pos_cmd: limiter.lim_cmd is in mm, x_axis.pos_cmd has no unit: " \
           "values pass unconverted" in run.warnings
    assert "connection x_axis.pos -> seq.x_pos: seq.x_pos is in mm, x_axis.pos has no unit: values pass " \
           "unconverted" in run.warnings


def test_an_input_nothing_drives_is_named(foreign, project, tmp_path):
    system = with_plant("lathe_taper", "PlantAxis", drop=("x_axis.in_position -> seq.x_in_position",))
    run = simulate(str(packed(system, foreign, tmp_path)))
    assert [w for w in run.warnings if w.startswith("seq.x_in_position")] == [
        "seq.x_in_position: an input that no connection drives and no start value is given for: it keeps its FMU's "
        "start value true"]
    shipped = simulate("lathe_taper", stop_time=0.01)
    assert shipped.warnings == []          # the free inputs of a shipped system are meant to be free


@pytest.mark.parametrize("connector, refusal", [
    (("pos_cmd", "output", "Real", "mm"), r"connector x_axis\.pos_cmd: declared output, but the FMU's pos_cmd is "
                                          "input"),
    (("pos", "output", "Integer", None), r"connector x_axis\.pos: declared Integer, but the FMU's pos is Real"),
    (("pos", "output", "Real", "s"), r"connector x_axis\.pos: declared in s \(s\), but the FMU's pos is in mm"),
    (("position", "output", "Real", "mm"), r"connector x_axis\.position: x_axis's FMU has no variable 'position'"),
])
def test_every_ssd_connector_is_checked_against_its_fmu(foreign, project, tmp_path, connector, refusal):
    system = with_plant("lathe_taper", "PlantAxis")
    system.component("x_axis").connectors = [connector]
    with pytest.raises(SystemDefinitionError, match=refusal):
        OpenSystem(packed(system, foreign, tmp_path))


def test_a_foreign_fmus_min_and_max_hold_for_start_values_and_parameter_sets(foreign, project, tmp_path):
    from ncfmu.errors import ConfigError
    system = System("gain", [Component("feed", "Feedthrough", {"gain": 2.0})], [], 1.0)
    archive = packed(system, foreign, tmp_path / "ok")
    with OpenSystem(archive) as opened:
        with pytest.raises(ConfigError, match=r"feed\.gain = 0\.3: must be in \[0\.5, 4\]"):
            opened.run(start_values={"feed.gain": 0.3})
    system.components[0].parameters["gain"] = 5.0          # the .ssv's value
    with OpenSystem(packed(system, foreign, tmp_path / "ssv")) as opened:
        with pytest.raises(ConfigError, match=r"feed\.gain = 5\.0: must be in \[0\.5, 4\]"):
            opened.run()
