"""The built FMUs: every model built, code isolation, refused parameters, runtime input faults."""

import math
import sys

import pytest

from ncfmu.controllers import CutSequencer
from ncfmu.errors import SimulationError
from ncfmu.systems import parameters

#: The lathe's registers and limit table, from its system definition (the FMUs' own defaults are neutral).
LATHE_SEQ, LATHE_LIMITER = parameters("lathe_roughing", "seq"), parameters("lathe_roughing", "limiter")


def test_every_model_is_built(fmus):
    # fmpy's validation of each FMU (and the SSP schema of each system) is `ncfmu validate`: test_cli
    assert set(fmus) == {"AreaLimiter", "ContourInterpolator", "CutSequencer", "OperatorPanel", "ProgrammableFeed",
                         "ServoAxis", "SpindleDrive"}


def test_model_description_carries_units_and_initial_unknowns(fmus):
    from fmpy import read_model_description
    md = read_model_description(str(fmus["ServoAxis"]))
    units = {u.name for u in md.unitDefinitions}
    assert {"mm", "mm/s", "N.m"} <= units
    pos = next(v for v in md.modelVariables if v.name == "pos")
    assert pos.unit == "mm" and pos.description
    assert {u.variable.name for u in md.initialUnknowns} == {v.name for v in md.modelVariables
                                                             if v.causality == "output"}
    assert md.defaultExperiment.stepSize == "0.001"


def test_fmu_runs_the_code_it_was_built_from(fmus, fmu_runner, monkeypatch):
    """Break the in-process ncfmu: the FMU must not notice (it runs its own vendored copy)."""
    import ncfmu.controllers.sequencer as src
    for entry in ("step", "step_then_count_messages"):           # the latter is what the binary calls
        monkeypatch.setattr(src.CutSequencer, entry, lambda *a, **k: (_ for _ in ()).throw(RuntimeError("dev copy")))
    monkeypatch.setattr(src, "MAX_BLOCKS", 1)
    r = fmu_runner(fmus["CutSequencer"]).start()
    r.set(start=True)
    for i in range(100):
        r.slave.do_step(i * 1e-3, 1e-3)
    assert r.get("subcycle") == 1 and r.get("x_cmd") < 30.0
    vendored = [m for m in sys.modules if m.startswith("ncfmu_")]
    assert vendored, "the FMU imported a content-addressed copy of ncfmu"


@pytest.mark.parametrize("name, value, rule", [
    ("block[1].Xd", -0.5, "must be > 0"),
    ("block[1].N", 0, "must be in 1..10000"),
    ("block[2].Zp", 0.0, "must be > 0"),
    ("n_blocks", 12, "must be in 1..8"),
    ("block[1].feed", 0.0, "must be > 0"),
    ("x_start", math.nan, "must be finite"),
])
def test_bad_registers_refused_at_initialisation(fmus, fmu_runner, name, value, rule):
    r = fmu_runner(fmus["CutSequencer"])
    with pytest.raises(SimulationError) as err:
        r.start(**{**LATHE_SEQ, name: value})
    text = str(err.value)
    assert "fmi2ExitInitializationMode returned fmi2Error" in text
    assert f"{name} = " in text and rule in text
    assert any(lvl == "error" and name in msg and rule in msg for lvl, msg in r.slave.messages)
    # fmi2Error, not fmi2Fatal: the instance lives on, can be reset and initialised with good registers
    r.slave.reset()
    r.slave.initialize(0.0, 1.0)
    r.slave.do_step(0.0, 1e-3)
    assert r.get("alarm") == 0 and r.get("x_cmd") == CutSequencer.default_parameters()["x_start"]   # the defaults


def test_nan_position_raises_alarm_and_stops_under_control(fmus, fmu_runner):
    r = fmu_runner(fmus["CutSequencer"]).start()
    r.set(start=True)
    t = 0.0
    for _ in range(30):
        r.slave.do_step(t, 1e-3)
        t += 1e-3
        r.set(x_pos=r.get("x_cmd"), z_pos=r.get("z_cmd"))
    before, v0 = r.get("x_cmd"), r.get("x_vff")
    assert v0 < -10.0                                    # infeed under way
    r.set(x_pos=math.nan)
    vffs = [v0]
    for _ in range(60):
        r.slave.do_step(t, 1e-3)
        t += 1e-3
        vffs.append(r.get("x_vff"))
        assert math.isfinite(r.get("x_cmd"))
    assert r.get("alarm")
    # a controlled stop at accel = 500 mm/s2, along the infeed, then at rest
    assert max(abs(b - a) for a, b in zip(vffs, vffs[1:])) <= 500.0 * 1e-3 * (1 + 1e-9)
    assert vffs[-1] == 0.0 and 0 < before - r.get("x_cmd") <= v0 * v0 / 1000.0 + abs(v0) * 1e-3
    rest = (r.get("x_cmd"), r.get("z_cmd"))
    r.slave.do_step(t, 1e-3)
    assert (r.get("x_cmd"), r.get("z_cmd")) == rest and r.get("x_vff") == 0.0
    assert any("x_pos" in msg and lvl == "error" for lvl, msg in r.slave.messages)


def test_two_instances_of_one_fmu_in_one_process(fmus, fmu_runner):
    a = fmu_runner(fmus["ServoAxis"], "x_axis").start(pos_start=1.0)
    b = fmu_runner(fmus["ServoAxis"], "z_axis").start(pos_start=2.0)
    c = fmu_runner(fmus["ServoAxis"], "y_axis").start(pos_start=3.0)
    assert (a.get("pos"), b.get("pos"), c.get("pos")) == (1.0, 2.0, 3.0)


@pytest.mark.parametrize("name, value, rule", [
    ("region[2].ref_max", -50.0, "boundaries must increase strictly"),
    ("region[1].lim_min", 2e6, "must be <= region[1].lim_max"),
    ("n_regions", 40, "must be in 1..32"),
    ("monitor_period", -0.005, "must be > 0"),
])
def test_bad_limit_table_refused_at_initialisation(fmus, fmu_runner, name, value, rule):
    r = fmu_runner(fmus["AreaLimiter"])
    with pytest.raises(SimulationError) as err:
        r.start(**{**LATHE_LIMITER, name: value})
    assert "returned fmi2Error" in str(err.value)
    assert f"{name} = " in str(err.value) and rule in str(err.value)


def test_a_controller_exception_fails_the_step_with_fmi2error(fmus, fmu_runner, monkeypatch):
    """A defect inside the controller: fmi2Error and the exception in the log, the host keeps running."""
    r = fmu_runner(fmus["OperatorPanel"]).start()
    from ncfmu.fmi.builder import vendored_package
    vendored = sys.modules[f"{vendored_package(fmus['OperatorPanel'])}.controllers.panel"]   # the FMU's own copy

    def broken(self, t, dt, inputs):
        raise ZeroDivisionError("deliberate defect")
    # the method the binary's DoStep calls (compiled, it calls ``step`` natively: a patched ``step`` is not seen),
    # before the first step (the binary takes it then and holds it while only steps run)
    monkeypatch.setattr(vendored.OperatorPanel, "step_then_count_messages", broken)
    with pytest.raises(SimulationError) as err:
        r.slave.do_step(0.0, 1e-3)
    assert "returned fmi2Error" in str(err.value) and "deliberate defect" in str(err.value)
