"""G32, G92 and G76 as Fanuc's 0i-T manual defines their passes (plain-Python planner, no FMU): the commanded
X of each pass (diameters and radii), G76's constant chip area with its least depth, finishing passes, chamfer and
flank infeed, G92's modal passes -- and the refusals, naming the line."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ncfmu.controllers import lathe_program
from ncfmu.controllers.thread_cycles import g76_depths
from ncfmu.errors import ProgramError, ProgramErrors

#: The M30x2 of the issue: root diameter 27.546, thread height 1.227, first depth 0.4, least 0.1, allowance 0.05.
M30 = """G97 S500 M03
G00 X32. Z5.
G76 P020060 Q100 R0.05
G76 X27.546 Z-30. P1227 Q400 F2.0
G00 X40.
M30"""


def _plan(text: str, start: tuple[float, float] = (20.0, 10.0)):
    return lathe_program.plan(text, start, 50.0)


def _cuts(segs, cycle: int):
    return [g for g in segs if g.cycle == cycle and g.lead > 0 and not g.continues]


def _refusal(text: str) -> ProgramError:
    with pytest.raises((ProgramError, ProgramErrors)) as info:
        _plan(text)
    err = info.value
    return err.errors[0] if isinstance(err, ProgramErrors) else err


def test_g76_passes_are_fanucs_constant_chip_area_with_least_depth_and_finishing_passes():
    cuts = _cuts(_plan(M30), 76)
    # cumulative depth Q*sqrt(n) = 0.4, 0.566, 0.693, 0.8; then sqrt's increment 0.094 < Q100's 0.1: +0.1 each
    # (0.9, 1.0, 1.1), clamped at the height less the allowance 1.227 - 0.05 = 1.177; then P02: two at 1.227
    depths = [0.4, 0.4 * math.sqrt(2), 0.4 * math.sqrt(3), 0.8, 0.9, 1.0, 1.1, 1.177, 1.227, 1.227]
    crest = 27.546 / 2 + 1.227                                   # 15.0: the major radius
    assert len(cuts) == len(depths)
    for g, d in zip(cuts, depths):
        assert g.element.start[1] == pytest.approx(crest - d, abs=1e-9)          # radius
        assert 2 * g.element.end[1] == pytest.approx(2 * (crest - d), abs=1e-9)  # diameter
        assert g.lead == 2.0 and g.rate == pytest.approx(2.0 * 500 / 60)
        # the flank infeed (a = 60): a pass stands (k - d) tan 30 deg behind the finishing pass, whole
        behind = (1.227 - d) * math.tan(math.radians(30))
        assert g.element.start[0] == pytest.approx(5.0 + behind, abs=1e-9)
        assert g.element.end[0] == pytest.approx(-30.0 + behind, abs=1e-9)
    assert [g.pass_no for g in cuts] == list(range(1, 11))
    assert cuts[-1].element.end == pytest.approx((-30.0, 13.773))          # the bottom at radius 13.773
    assert 2 * cuts[-1].element.end[1] == pytest.approx(27.546)


def test_g76_each_pass_is_rapid_in_thread_rapid_out_rapid_back():
    segs = [g for g in _plan(M30) if g.cycle == 76]
    assert [g.subcycle for g in segs] == [1, 2, 3, 4] * 10
    for k in range(10):
        infeed, cut, out, back = segs[4 * k: 4 * k + 4]
        assert not infeed.feed and not out.feed and not back.feed and cut.feed
        assert infeed.element.start == pytest.approx((5.0, 16.0)) and back.element.end == pytest.approx((5.0, 16.0))
        assert out.element.end[1] == pytest.approx(16.0) and out.element.start == cut.element.end


def test_g76_chamfer_pulls_out_at_45_degrees_over_r_tenths_of_the_lead_following_the_spindle():
    segs = _plan(M30.replace("P020060", "P021560"))        # r = 15: 1.5 leads = 3 mm
    cuts = [g for g in segs if g.cycle == 76 and g.lead > 0]
    assert len(cuts) == 20
    for main, chamfer in zip(cuts[::2], cuts[1::2]):
        assert not main.continues and chamfer.continues          # one pass: no second wait for the marker
        assert chamfer.element.start == main.element.end
        dz = chamfer.element.start[0] - chamfer.element.end[0]
        dx = chamfer.element.end[1] - chamfer.element.start[1]
        assert dz == pytest.approx(3.0) and dx == pytest.approx(3.0)        # 45 deg, out of the part
    last = cuts[-1]
    assert last.element.end[0] == pytest.approx(-30.0)


def test_g76_tool_angle_zero_plunges_straight_in():
    cuts = _cuts(_plan(M30.replace("P020060", "P010000")), 76)
    assert {round(g.element.start[0], 12) for g in cuts} == {5.0}
    assert len(cuts) == 8 + 1                           # m = 1


def test_g92_modal_passes_with_x_alone_and_a_taper():
    segs = _plan("""G97 S600 M04
G00 X32. Z4.
G92 X29.3 Z-25. F1.5
X28.9
U-3.4
G92 X28. Z-25. R-0.5 F1.5
G00 X40.
M30""")
    passes = [g for g in segs if g.cycle == 92]
    assert [g.subcycle for g in passes] == [1, 2, 3, 4] * 4
    cuts = [g for g in passes if g.subcycle == 2]
    assert [2 * g.element.end[1] for g in cuts] == pytest.approx([29.3, 28.9, 28.6, 28.0])
    assert [g.pass_no for g in cuts] == [1, 2, 3, 1]
    assert all(g.element.end[0] == pytest.approx(-25.0) and g.element.start[0] == pytest.approx(4.0) for g in cuts)
    assert cuts[3].element.start[1] == pytest.approx(14.0 - 0.5)            # R: the start's radius minus the end's
    assert all(g.lead == 1.5 and g.modal.spindle == -1 for g in cuts)
    for k in range(4):
        infeed, cut, out, back = passes[4 * k: 4 * k + 4]
        assert infeed.element.start == pytest.approx((4.0, 16.0)) == back.element.end
        assert infeed.element.end == cut.element.start and out.element.end == pytest.approx((-25.0, 16.0))


def test_g32_cuts_and_a_following_g32_continues_the_helix():
    segs = _plan("""G97 S400 M03
G00 X20. Z3.
G32 Z-20. F1.
G32 X24. Z-24.
G00 X30.
M30""")
    cuts = [g for g in segs if g.cycle == 32]
    assert [g.continues for g in cuts] == [False, True]
    assert cuts[0].element.start == pytest.approx((3.0, 10.0)) and cuts[0].element.end == pytest.approx((-20.0, 10.0))
    assert cuts[1].element.end == pytest.approx((-24.0, 12.0)) and cuts[1].lead == 1.0


@pytest.mark.parametrize("text, line, needle", [
    ("G97 S500 M03\nG00 X32. Z5.\nG76 X27.546 Z-30. P1227 Q400 F2.0\nM30", 3, "G76's first block"),
    ("G97 S500 M03\nG00 X32. Z5.\nG32 Z-30. F0\nM30", 3, "F"),
    ("G97 S500 M03\nG00 X29. Z5.\nG76 P020060 Q100 R0.05\nG76 X27.546 Z-30. P1227 Q400 F2.0\nM30", 4,
     "larger than the depth available"),
    ("G00 X32. Z5.\nG76 P020060 Q100 R0.05\nG76 X27.546 Z-30. P1227 Q400 F2.0\nM30", 3, "spindle stopped"),
    ("G97 S500 M03\nM05\nG00 X32. Z5.\nG92 X29. Z-30. F2.\nM30", 4, "spindle stopped"),
    ("G50 S2500\nG96 S150 M03\nG00 X32. Z5.\nG32 Z-30. F2.\nM30", 4, "G96"),
    ("G97 S500 M03\nG00 X32. Z5.\nG32 Z-30. F2. S800\nM30", 3, "spindle speed"),
    ("G97 S500 M03\nG00 X32. Z5.\nG92 X29. Z-30. F2.\nM05 X28.\nM30", 4, "M05"),
    ("G97 S500 M03\nG00 X32. Z5.\nG32 X10. Z4. F2.\nM30", 3, "45 degrees"),
    ("G97 S500 M03\nG00 X32. Z5.\nG32 Z-30.\nM30", 3, "no lead"),
    ("G97 S500 M03\nG00 X32. Z5.\nG76 P020060 Q100 R0.05\nG76 X27.546 Z-30. P1227 Q400 F-2.\nM30", 4, "F"),
    ("G97 S500 M03\nG00 X32. Z5.\nG92 X33. Z-30. F2.\nM30", 3, "below the start point"),
    ("G97 S500 M03\nG00 X32. Z5.\nG76 P020061 Q100 R0.05\nM30", 3, "tool angle"),
    ("G97 S500 M03\nG00 X32. Z5.\nG76 P020060 Q100 R2.\nG76 X27.546 Z-30. P1227 Q400 F2.0\nM30", 4, "allowance"),
    ("G97 S500 M03\nG00 X300. Z5.\nG76 P090060 Q1 R0\nG76 X27.546 Z-30. P99000 Q1 F2.0\nM30", 4,
     "more than 1000 roughing passes"),
    ("G97 S500 M03\nG00 X300. Z5.\nG76 P090060 Q100 R0\n" + "G76 X27.546 Z-30. P99000 Q1 F2.0\n" * 6 + "M30", 9,
     "more than 20000 planned thread moves"),
    # the red team's program: G96 S0 with G99 is accepted on 9c586ec and the tool never moves
    ("G50 S2500\nG99\nG96 S0 M03\nG01 X50. F0.2\nM30", 3, "S0 under G96"),
])
def test_refusals_name_the_line(text, line, needle):
    err = _refusal(text)
    assert err.line_no == line
    assert needle in str(err)


def test_g96_without_s_then_a_feed_per_revolution_is_refused():
    err = _refusal("G50 S2500\nG99 G96 M03\nG01 X50. F0.2\nM30")
    assert err.line_no == 3 and "spindle stopped" in str(err)


def test_a_thread_inside_a_g71_profile_is_refused():
    err = _refusal("G97 S500 M03\nG00 X60. Z2.\nG71 U1. R0.5\nG71 P10 Q20 U0.4 W0.1 F100.\nN10 G00 X30.\n"
                   "G32 Z-20. F2.\nN20 G01 X60.\nM30")
    assert err.line_no == 6 and "inside a profile" in str(err)


@given(height=st.floats(0.2, 5.0), first=st.floats(0.05, 1.0), least=st.floats(0.01, 0.3),
       allowance=st.floats(0.0, 0.15), finishing=st.integers(1, 5))
def test_g76_depths_constant_chip_area_never_less_than_the_least(height, first, least, allowance, finishing):
    depths = g76_depths(height, first, least, allowance, finishing)
    rough = depths[:-finishing]
    assert depths[-finishing:] == [height] * finishing
    assert rough[-1] == pytest.approx(height - allowance)
    previous = 0.0
    for n, d in enumerate(rough, start=1):
        assert d > previous
        assert d >= first * math.sqrt(n) - 1e-12 or d == pytest.approx(height - allowance)
        if d < height - allowance - 1e-12:
            assert d - previous >= least - 1e-12                     # never less than the least depth
            assert d == pytest.approx(max(first * math.sqrt(n), previous + least))
        previous = d
