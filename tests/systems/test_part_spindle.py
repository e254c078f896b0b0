"""The part check's spindle: material removed while the spindle stands is a crash, named by its line.

The oracle reads the trajectory alone (which line ran, where the tool stood, the spindle's actual speed) and the
program's own numbers (the first pass leaves radius 28; the feed after M05 goes to radius 27): none of it goes
through the material-removal engine.
"""

from __future__ import annotations

import numpy as np
import pytest

from ncfmu.machining.removal import STANDING, TOUCH
from ncfmu.systems.part import STANDSTILL_RPM

pytestmark = pytest.mark.slow

#: One pass at X56 (radius 28) with the spindle at 800 rev/min, M05, then a feed (G98: per minute, so it moves
#: without the spindle) at X54 (radius 27) into the bar the first pass left at radius 28: 1 mm deep, text line 10.
PROGRAM = """%
O2001 (A CUT, M05, THEN A FEED INTO THE BAR WITH THE SPINDLE STOPPED)
N1 G21 G40 G98
N2 G97 S800 M03
N3 G00 X56. Z2.
N4 G01 Z-20. F300.
N5 G00 X60.
N6 Z2. M05
N7 X54.
N8 G01 Z-10. F300.
N9 G00 X60.
N10 Z2.
N11 M30
%
"""
FEED_LINE = PROGRAM.splitlines().index("N8 G01 Z-10. F300.") + 1


def test_a_feed_into_the_bar_after_m05_is_a_crash_named_by_its_line(ncfmu_run):
    r = ncfmu_run("lathe_roughing", stop_time=12.0, start_values={"seq.program": PROGRAM})
    line, z, x, rpm = r["seq.line"], r["z_axis.pos"], r["x_axis.pos"], r["spindle.speed"]
    assert FEED_LINE == 10
    # the first pass cut at speed: the spindle at 800 rev/min (within the arrival band) while the tool was in
    cutting = (line == 6) & (z < -TOUCH)
    assert cutting.any() and np.abs(rpm[cutting] - 800.0).max() < 0.05 * 800.0
    crashes = r.part.crashes
    assert [(c.line, c.what) for c in crashes] == [(FEED_LINE, STANDING)]
    # how deep: from the radius the first pass left (28) to where the tool fed (27, as the axis stood)
    inside = (line == FEED_LINE) & (z < -TOUCH)
    assert crashes[0].depth_mm == pytest.approx(28.0 - x[inside].mean(), abs=0.002)
    assert crashes[0].depth_mm == pytest.approx(1.0, abs=0.01)
    # when: the first row of that line where the tool was in the bar by more than a touch -- the spindle stood
    first = int(np.argmax(inside))
    assert rpm[first] == pytest.approx(0.0, abs=STANDSTILL_RPM)
    assert crashes[0].t == pytest.approx(float(r.time[first]), abs=0.003)
    assert r.part.within_tolerance is False


def test_the_same_program_without_m05_cuts_at_speed_and_does_not_crash(ncfmu_run):
    r = ncfmu_run("lathe_roughing", stop_time=12.0,
                  start_values={"seq.program": PROGRAM.replace("N6 Z2. M05", "N6 Z2.")})
    inside = (r["seq.line"] == FEED_LINE) & (r["z_axis.pos"] < -TOUCH)
    assert inside.any() and np.abs(r["spindle.speed"][inside] - 800.0).max() < 0.05 * 800.0
    assert r.part.crashes == []


def test_the_registers_cycles_are_not_judged_by_the_spindle(ncfmu_run):
    # the registers' cycles command no spindle (the seed's sequencer has no spindle words: the operator runs it):
    # their cuts are no crash
    r = ncfmu_run("lathe_taper")
    assert np.abs(r["spindle.speed"]).max() < STANDSTILL_RPM
    assert r.part.crashes == [] and r.part.within_tolerance is True


#: A G71/G70 part program that never starts the spindle (G98: its feeds move without it), numbered by tens.
NO_SPINDLE = """%
O2002 (A WHOLE PART, NO M03)
N10 G18 G21 G90 G8 G98
N20 G00 X30 Z2
N30 G71 U1.5 R0.5
N40 G71 P50 Q70 U0.2 W0.1 F300
N50 G00 X26
N60 G01 Z-10
N70 X30
N80 G70 P50 Q70 F300
N90 M30
%
"""


def test_a_program_that_never_starts_the_spindle_crashes_at_its_first_cut_named_by_line_and_n(ncfmu_run, tmp_path,
                                                                                            capsys):
    """Before issue 51 the spindle rule held only for programs that started the spindle: this whole part was
    'within 0.0100 mm', exit 0."""
    import json

    from ncfmu.cli import main
    code = main(["run", "lathe_roughing", "--stop-time", "12", "--set", f"seq.program={NO_SPINDLE}",
                 "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 3
    first_cut = NO_SPINDLE.splitlines().index("N40 G71 P50 Q70 U0.2 W0.1 F300") + 1      # text line 6: G71 cuts
    written = json.loads((tmp_path / "lathe_roughing.part.json").read_text())
    crashes = written["crashes"]
    assert crashes and {c["what"] for c in crashes} == {STANDING}
    assert crashes[0]["line"] == first_cut and crashes[0]["n"] == 40
    assert f"line {first_cut} (N40): {STANDING}" in out
    assert "within" not in "".join(line for line in out.splitlines() if "part:" in line)
    assert written["within_tolerance"] is False
