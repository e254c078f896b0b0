"""Each system defined once: its definition and its report agree, and the controllers carry no scenario."""

import numpy as np
import pytest

from ncfmu.controllers import AreaLimiter, ContourInterpolator, CutSequencer, ProgrammableFeed
from ncfmu.cosim.result import Result
from ncfmu.systems import MODELS, SYSTEMS, get_system, parameters, report_for
from ncfmu.systems.report import Axes

DT = 1e-3


@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_every_report_reads_outputs_its_system_has(name):
    system, report = get_system(name), SYSTEMS[name].report
    models = {c.name: c.model for c in system.components}
    for qualified in report.record():
        instance, _, variable = qualified.partition(".")
        outputs = {p.name for p in MODELS[models[instance]].ports("output")}
        assert variable in outputs, f"{name}: the report reads {qualified}, which {models[instance]} does not output"
    assert set(report.axes) == {i for i, m in models.items() if m == "ServoAxis"}
    if report.plane is not None:
        assert {report.plane.horizontal, report.plane.vertical} <= set(report.axes)


def test_an_ssp_of_another_make_gets_the_generic_report():
    models = {c.name: c.model for c in get_system("mill_contour").components}
    assert report_for("mill_contour", models) is SYSTEMS["mill_contour"].report
    renamed = {("cnc" if k == "contour" else k): v for k, v in models.items()}
    generic = report_for("mill_contour", renamed)
    assert generic.plane is None and generic.record() == ["x_axis.pos", "x_axis.following_error", "y_axis.pos",
                                                           "y_axis.following_error"]
    assert [type(p) for p in generic.parts] == [Axes]


def test_metrics_and_summary_read_the_parameters_of_the_run():
    """A perfect-servo run of a 2 mm oversize cutter: its report, given that run's parameters, finds the cutter
    on its path; given the system's (0.4 mm), it finds it 0.8 mm off."""
    used = {**parameters("mill_contour", "contour"), "diameter_delta": 2.0}
    c = ContourInterpolator(**used)
    inputs = dict(c.default_inputs(), start=True, x_pos=c.x_start, y_pos=c.y_start)
    rows = []
    for k in range(60_000):
        o = c.step(k * DT, DT, inputs)
        inputs.update(x_pos=o["x_cmd"], y_pos=o["y_cmd"])
        rows.append(((k + 1) * DT, o["x_cmd"], o["y_cmd"], 0.0, 0.0, o["segment"], o["done"], o["alarm"]))
        if o["done"]:
            break
    names = ["time", "x_axis.pos", "y_axis.pos", "x_axis.following_error", "y_axis.following_error",
             "contour.segment", "contour.done", "contour.alarm"]
    data = np.array(rows, dtype=[(n, float) for n in names])
    report = SYSTEMS["mill_contour"].report
    ran = report.metrics(Result(data, "mill_contour", 1.0), {"contour": used})
    assert ran["max_contour_error_mm"] <= c.dda_unit * 1.01 and ran["alarms"] == 0
    assert ran["cycle_time_s"] == pytest.approx(rows[-1][0])
    other = report.metrics(Result(data, "mill_contour", 1.0), {"contour": parameters("mill_contour", "contour")})
    assert other["max_contour_error_mm"] >= 0.8 - 0.01       # 0.8 along the sides, more at the corners


def test_controller_defaults_carry_no_system_scenario():
    """An FMU's start values run no system's scenario: the limiter limits nothing, the feed's cycle is empty
    (its EMB returns X to the origin), the contour is one 10 mm move, the sequencer one 1 mm pass over 10 mm;
    the scenarios live in the systems."""
    limiter = AreaLimiter()
    inputs = dict(limiter.default_inputs())
    ref = lim = 0.0
    for k in range(1, 5001):                       # toward Z -500, X -900 up to 100 and 180 mm/s: passed through
        # accelerating as an interpolator does (the limiter smooths a faster velocity step, whatever its table)
        v_ref, v_lim = -min(100.0, limiter.decel * k * DT), -min(180.0, limiter.decel * k * DT)
        ref, lim = ref + v_ref * DT, lim + v_lim * DT
        inputs.update(ref_cmd_in=ref, lim_cmd_in=lim, ref_vff_in=v_ref, lim_vff_in=v_lim, ref_pos=ref, lim_pos=lim)
        o = limiter.step(k * DT, DT, inputs)
        assert (o["ref_cmd"], o["lim_cmd"], o["alarm"], o["blocked"]) == (ref, lim, False, 0)

    feed = ProgrammableFeed()
    inputs = dict(feed.default_inputs(), start=True)
    for k in range(100):
        o = feed.step(k * DT, DT, inputs)
        inputs["start"] = False
    assert o["x_cmd"] == 0.0 and not o["run"] and not o["alarm"]

    contour = ContourInterpolator()
    assert [(m.element.start, m.element.end) for m in contour.tool_path][-1] == ((0.0, 0.0), (10.0, 0.0))

    seq = CutSequencer()                           # one pass 1 mm deep over 10 mm from X 10, Z 0, and back
    inputs = dict(seq.default_inputs(), start=True)
    xs, zs = [], []
    for k in range(6000):                          # the cut: 10 mm at 4 mm/s
        o = seq.step(k * DT, DT, inputs)
        inputs.update(start=False, x_pos=o["x_cmd"], z_pos=o["z_cmd"])
        xs.append(o["x_cmd"])
        zs.append(o["z_cmd"])
        if o["done"]:
            break
    assert o["done"] and not o["alarm"] and (min(xs), min(zs)) == (9.0, -10.0) and (xs[-1], zs[-1]) == (10.0, 0.0)
    lathe = parameters("lathe_roughing", "seq")
    assert all(lathe[name] != port.start for name, port in ((p.name, p) for p in CutSequencer.ports("parameter"))
               if name in ("x_start", "z_start", "block[1].Zp", "block[1].N"))


def _outside(port):
    """A value just outside the port's range."""
    if port.min is not None:
        return port.min if port.min_exclusive else port.min - max(1.0, abs(port.min))
    return port.max + max(1.0, abs(port.max))


@pytest.mark.parametrize("model", sorted(MODELS))
def test_one_rule_per_parameter_in_the_port_the_model_description_and_the_message(model, fmus):
    """The range a port states is the modelDescription's range, and the rule a value outside it is refused by,
    with a message naming the parameter, the value and that rule (the same text an FMU logs)."""
    from fmpy import read_model_description

    from ncfmu.errors import ConfigError
    logic = MODELS[model]
    described = {v.name: v for v in read_model_description(str(fmus[model])).modelVariables}
    ranged = [p for p in logic.ports("parameter") if p.min is not None or p.max is not None]
    assert ranged
    for port in ranged:
        v = described[port.name]
        assert (None if v.min is None else float(v.min)) == port.min, port.name
        assert (None if v.max is None else float(v.max)) == port.max, port.name
        value = _outside(port)
        with pytest.raises(ConfigError) as err:
            logic(**{port.name: value})
        assert err.value.variable == port.name and f"{port.name} = {value!r}: {port.rule()}" in str(err.value)
