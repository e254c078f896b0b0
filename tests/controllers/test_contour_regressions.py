"""Defects a red-team review of the contour rewrite found, each a test that failed before its fix."""

import math

import numpy as np
import pytest
from physics import drive_contour

from ncfmu.controllers.contour import ContourInterpolator
from ncfmu.controllers.rs274 import parse
from ncfmu.errors import ConfigError, ProgramError


def circle_in_arcs(n, radius, decimals, a0, comp):
    """A full circle written as n G03 arcs with coordinates rounded to ``decimals``: its junctions turn by
    rounding noise only (1e-9 .. 1e-5 rad), they are tangent in all but the last digits."""
    p = [(radius * math.cos(a0 + 2 * math.pi * k / n), radius * math.sin(a0 + 2 * math.pi * k / n)) for k in range(n)]

    def f(v):
        return f"{v:.{decimals}f}"
    lines = ["F600", f"{comp} G01 X{f(p[0][0])} Y{f(p[0][1])}"]
    for k in range(1, n + 1):
        q, e = p[k - 1], p[k % n]
        lines.append(f"G03 X{f(e[0])} Y{f(e[1])} I{f(-q[0])} J{f(-q[1])}")
    lines += [f"G40 G01 X{f(2 * p[0][0])} Y{f(2 * p[0][1])}", "M30"]
    return "\n".join(lines), (round(2 * p[0][0], decimals), round(2 * p[0][1], decimals))


@pytest.mark.parametrize("n", [2, 3, 4, 6])
@pytest.mark.parametrize("decimals", [3, 4, 6])
@pytest.mark.parametrize("comp", ["G41", "G42"])
def test_a_circle_split_into_arcs_is_compensated_not_refused(n, decimals, comp):
    refused = []
    for a in range(0, 90, 11):
        program, (sx, sy) = circle_in_arcs(n, 30.0, decimals, math.radians(a + 0.5), comp)
        c = ContourInterpolator(program=program, diameter_delta=1.0, x_start=sx, y_start=sy)
        if c.geometry_error:
            refused.append((a, c.geometry_error))
        else:       # the cutter centre on the circle of R -+ r
            r = 29.5 if comp == "G41" else 30.5
            for move in c.tool_path[1:-1]:
                for s in np.linspace(0, move.element.length, 7):
                    assert math.hypot(*move.element.point(s)) == pytest.approx(r, abs=2e-3)
    assert refused == []


def test_a_slot_with_rounded_ends_is_compensated():
    program = "\n".join(["F600", "G42 G01 X0 Y5", "G01 X40.0000", "G02 X40.0000 Y-5.0000 I0.0000 J-5.0000",
                         "G01 X0", "G02 X0 Y5 I0 J5", "G40 G01 X-10 Y20", "M30"])
    c = ContourInterpolator(program=program, diameter_delta=2.0, x_start=-10.0, y_start=20.0)
    assert c.geometry_error is None


def test_an_arc_keeps_its_programmed_centre_when_its_end_is_slightly_off_the_circle():
    # end 1 um inside the circle, 1 um from the start: the full circle the program means, not a 0.5 um arc
    (_, arc) = parse("F600\nG01 X10 Y0\nG02 X10.001 Y0 I10 J0\nM30", (0.0, 0.0))
    assert arc.element.center == (20.0, 0.0) and arc.element.radius == 10.0
    assert arc.element.sweep == pytest.approx(-2 * math.pi)
    # a short arc tangent to the line before it stays tangent: no kink from a centre moved 1.47 mm
    (line, arc) = parse("F600\nG01 X10 Y0\nG03 X10.010001 Y-0.001495 I0 J10\nM30", (0.0, 0.0))
    assert arc.element.center == (10.0, 10.0)
    assert arc.element.tangent(0.0) == pytest.approx(line.element.unit, abs=1e-12)


def test_an_arc_ending_where_it_starts_up_to_rounding_is_a_full_circle():
    (*_, arc) = parse("F600\nG91 G01 X0.1\nX0.2\nG90 G03 X0.3 Y0 I10 J0\nM30", (0.0, 0.0))
    assert arc.element.radius == pytest.approx(10.0) and arc.element.sweep == pytest.approx(2 * math.pi)


def test_an_arc_of_rounding_noise_is_a_program_error_not_a_crash():
    program = "F600\nG42 G01 X0.1 Y0\nG91 G01 X0.2\nG90 G03 X0.3 Y0 I10 J0\nG01 X0.3 Y10\nG40 G01 X-10 Y10\nM30"
    c = ContourInterpolator(program=program, diameter_delta=2.0, x_start=0.0, y_start=-10.0)
    rows = drive_contour(c)
    assert rows[-1, 5] == 1 or rows[-1, 6] == 1
    assert np.isfinite(rows[:, :4]).all()


@pytest.mark.slow
@pytest.mark.parametrize("program, block_line, feed", [
    ("G01 F6000 X50 Y0\nF60\nX100\nM30", 3, 1.0),                        # collinear: a tangent junction
    ("G01 F6000 X50 Y0\nG03 F60 X50 Y20 I0 J10\nM30", 2, 1.0),           # into a tangent arc
])
def test_a_lower_feed_in_the_next_block_is_reached_before_it(program, block_line, feed):
    c = ContourInterpolator(program=program, diameter_delta=0.0, x_start=0.0, y_start=0.0)
    rows = drive_contour(c)
    assert rows[-1, 5] == 1
    speed = np.hypot(rows[:, 2], rows[:, 3])
    assert speed[rows[:, 4] == block_line].max() <= feed * (1 + 1e-9)
    # and the override scales it: at 50 % the slower block runs at half its feed
    c = ContourInterpolator(program=program, diameter_delta=0.0, x_start=0.0, y_start=0.0)
    rows = drive_contour(c, feed_override=0.5)
    top = np.hypot(rows[:, 2], rows[:, 3])[rows[:, 4] == block_line].max()
    assert top <= 0.5 * feed * (1 + 1e-9)


@pytest.mark.parametrize("values, variable", [
    ({"dda_unit": 1e-310}, "dda_unit"),
    ({"diameter_delta": 1e308}, "diameter_delta"),
    ({"diameter_delta": 1e6}, "diameter_delta"),
    ({"point[2].x": 1e308}, "point[2].x"),
    ({"point[1].x": -1e308, "point[2].x": 1e308}, "point[1].x"),
])
def test_absurd_parameters_are_refused_by_name(values, variable):
    with pytest.raises(ConfigError) as err:
        ContourInterpolator(**values)
    assert err.value.variable == variable


@pytest.mark.parametrize("dt, accel", [(1e-5, 50.0), (1e-4, 5.0), (1e-3, 500.0)])
def test_an_exact_stop_never_drops_a_leftover_speed(dt, accel):
    for length in (0.012561258, 0.0314159, 0.049):
        c = ContourInterpolator(program=f"F600\nG01 X{length} Y0\nM30", diameter_delta=0.0, accel=accel,
                                x_start=0.0, y_start=0.0)
        rows = drive_contour(c, dt=dt)
        assert rows[-1, 5] == 1
        assert (np.abs(np.diff(rows[:, 2])) / dt).max() <= accel * (1 + 1e-9)
    c = ContourInterpolator(program="F600 G01 X0 Y0.001\nX0 Y2\nX0.001 Y-1\nM30", diameter_delta=0.0, accel=accel,
                            x_start=0.0, y_start=0.0)
    rows = drive_contour(c, dt=dt)
    assert rows[-1, 5] == 1
    assert (np.abs(np.diff(rows[:, 2:4], axis=0)) / dt).max() <= accel * (1 + 1e-9)


def test_programs_beyond_the_move_limit_are_refused():
    from ncfmu.controllers.rs274 import MAX_MOVES
    program = "F600\n" + "\n".join(f"G01 X{k % 2} Y{k}" for k in range(1, MAX_MOVES + 2)) + "\nM30"
    with pytest.raises(ProgramError, match=f"more than {MAX_MOVES} moves"):
        parse(program, (0.0, 0.0))
