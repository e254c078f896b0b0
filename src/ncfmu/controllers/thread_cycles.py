"""Threads as a Fanuc 0i-T cuts them (G code system A, mm, X a diameter): G32 one thread cut, G92 the
thread-cutting cycle, G76 the multiple threading cycle -- their passes planned as :class:`.g7x.Segment` s.

A thread move is a segment with a ``lead`` (mm of Z per spindle revolution): the sequencer starts it at the
spindle's one-revolution marker and commands Z from the **actual** spindle angle (``seq.revolutions``), X
following Z along the segment (a taper). A segment that ``continues`` the one before it starts where that one
ended in the spindle's angle, without waiting for the marker again (consecutive G32 blocks, G76's chamfer).
The lead is along Z: a taper steeper than 45 degrees (Fanuc then takes the lead along X) is refused.

Geometry in the (z, x) plane, X a radius (as :mod:`.lathe_program`). The passes of the cycles are the seed's
sub-cycles: SC1 the infeed (rapid), SC2 the thread cut (following the spindle), SC3 the retract in X (rapid),
SC4 the return in Z to the start point (rapid); ``sigma_x`` the pass's depth below the start point.

G92 X Z R F (Fanuc): from the start point S, X in at rapid to the thread's start (X/2 + R: R the radius of the
cut's start minus its end's, a taper), the thread to (Z, X/2), X out to S's X, Z back to S's Z. No chamfer.

G76 P(m)(r)(a) Q(least depth, um) R(finishing allowance d, mm) / G76 X Z R(i) P(k, um) Q(first depth, um) F:
the root (minor) diameter X at Z, the thread height k above it. The roughing passes take a constant chip area:
the n-th pass's cumulative depth is Q*sqrt(n), its increment never less than the least depth, until k - d;
then m finishing passes at the full depth k. The infeed runs along one flank of the tool angle a: a pass of
depth d_n stands (k - d_n) * tan(a/2) behind the finishing pass in Z (against the cut's direction), so the
tool's trailing edge follows the flank and its leading edge cuts (the finishing passes stand at the programmed
Z). The chamfer r (tenths of the lead) pulls out at 45 degrees over the thread's last r*L/10 mm of Z.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .g7x import EPS, NO_MODAL, Modal, Segment
from .geometry import Line, Point

#: Fanuc's G76 tool angles a (degrees): the third pair of digits of the first block's P.
TOOL_ANGLES = (0, 29, 30, 55, 60, 80)
#: More passes than this in one G76 are refused (a least depth of 1 um on a deep thread would plan thousands).
MAX_THREAD_PASSES = 1000


class ThreadError(ValueError):
    """A thread's numbers do not make a thread (the reader names the block and the word: ``word``)."""

    def __init__(self, word: str, reason: str) -> None:
        super().__init__(reason)
        self.word = word
        self.reason = reason


@dataclass(frozen=True)
class G76Setup:
    """G76's first block: m finishing passes, the chamfer r in tenths of the lead, the tool angle a (degrees),
    the least depth of cut (mm, radius) and the finishing allowance d (mm, radius)."""

    finishing: int
    chamfer: int
    angle: int
    least: float
    allowance: float


def g76_setup(p: float, q: float, r: float) -> G76Setup:
    """G76 P(m)(r)(a) Q(least depth, um) R(d, mm): checked."""
    if p != int(p) or not 0 <= p <= 999999:
        raise ThreadError("P", f"P{p:g}: G76's first P is six digits mmrraa (finishing passes, chamfer in tenths "
                               "of the lead, tool angle), e.g. P020060")
    m, rest = divmod(int(p), 10000)
    chamfer, angle = divmod(rest, 100)
    if m < 1:
        raise ThreadError("P", f"P{p:g}: the finishing passes m (P's first two digits) are 01..99")
    if angle not in TOOL_ANGLES:
        raise ThreadError("P", f"P{p:g}: the tool angle a (P's last two digits) {angle} is not one of Fanuc's "
                               f"{', '.join(str(a) for a in TOOL_ANGLES)}")
    if q != int(q) or q <= 0:
        raise ThreadError("Q", f"Q{q:g}: the least depth of cut is a whole number of um > 0 (Q100: 0.1 mm)")
    if r < 0:
        raise ThreadError("R", f"R{r:g}: the finishing allowance must be >= 0")
    return G76Setup(m, chamfer, angle, q / 1000.0, r)


def g76_depths(height: float, first: float, least: float, allowance: float, finishing: int) -> list[float]:
    """The cumulative depths (mm, radius, from the thread's crest) of G76's passes: roughing at ``first`` *
    sqrt(n), each at least ``least`` deeper than the one before, up to ``height`` - ``allowance``; then
    ``finishing`` passes at ``height``."""
    rough_to = height - allowance
    depths: list[float] = []
    d = 0.0
    n = 0
    while rough_to > EPS and d < rough_to - EPS:
        n += 1
        d = min(max(first * math.sqrt(n), d + least), rough_to)
        depths.append(d)
        if len(depths) > MAX_THREAD_PASSES:
            raise ThreadError("Q", f"more than {MAX_THREAD_PASSES} roughing passes: a larger first depth or least "
                                   "depth")
    return depths + [height] * finishing


def _thread_segment(start: Point, end: Point, lead: float, rate: float, sub: int, pass_no: int, sigma: float,
                    line: int, cycle: int, continues: bool = False) -> Segment:
    return Segment(Line(start, end), rate, True, sub, pass_no, sigma, line, cycle, lead=lead, continues=continues)


def check_thread(start: Point, end: Point) -> None:
    """A thread cut's ends: it moves in Z, at most 45 degrees from it (the lead is along Z)."""
    dz, dx = end[0] - start[0], end[1] - start[1]
    if abs(dz) <= EPS:
        raise ThreadError("Z", "a thread along X alone (a scroll) is not in the subset: the thread must move in Z")
    if abs(dx) > abs(dz) + EPS:
        raise ThreadError("X", f"a taper thread steeper than 45 degrees (X {abs(dx):g} mm radius over Z {abs(dz):g} "
                               "mm): Fanuc then takes the lead along X, which is not in the subset")


def thread_rate(lead: float, modal: Modal) -> float:
    """The thread's nominal rate along Z, mm/s: the lead at the commanded spindle speed."""
    return lead * modal.s / 60.0


def plan_g32(start: Point, end: Point, lead: float, modal: Modal, line: int, continues: bool) -> Segment:
    check_thread(start, end)
    return _thread_segment(start, end, lead, thread_rate(lead, modal), 0, 0, 0.0, line, 32, continues)


def _pass(out: list[Segment], s: Point, cut_start: Point, cut_end: Point, chamfer_end: Point | None, lead: float,
          rate: float, rapid: float, pass_no: int, line: int, cycle: int) -> None:
    """One pass from the start point ``s``: SC1 rapid to ``cut_start``, SC2 the thread to ``cut_end`` (and the
    chamfer to ``chamfer_end``), SC3 X out to s's X, SC4 Z back to s."""
    sigma = s[1] - cut_start[1]
    out.append(Segment(Line(s, cut_start), rapid, False, 1, pass_no, sigma, line, cycle))
    out.append(_thread_segment(cut_start, cut_end, lead, rate, 2, pass_no, sigma, line, cycle))
    here = cut_end
    if chamfer_end is not None:
        out.append(_thread_segment(cut_end, chamfer_end, lead, rate, 2, pass_no, sigma, line, cycle, True))
        here = chamfer_end
    out.append(Segment(Line(here, (here[0], s[1])), rapid, False, 3, pass_no, sigma, line, cycle))
    out.append(Segment(Line((here[0], s[1]), s), rapid, False, 4, pass_no, sigma, line, cycle))


def plan_g92(s: Point, root_end: Point, taper: float, lead: float, modal: Modal, rapid: float, pass_no: int,
             line: int) -> list[Segment]:
    """One G92 pass from the start point ``s`` ((z, x)) to the thread's end ``root_end``, its start ``taper``
    (R, radius) above the end's X."""
    cut_start = (s[0], root_end[1] + taper)
    check_thread(cut_start, root_end)
    if cut_start[1] >= s[1] - EPS or root_end[1] >= s[1] - EPS:
        low, high = sorted((cut_start[1], root_end[1]))
        raise ThreadError("X", f"the thread (X {2 * low:g}..{2 * high:g} on the diameter) does not lie below the "
                               f"start point's X {2 * s[1]:g}: G92 cuts "
                               "from a start point above the thread")
    out: list[Segment] = []
    _pass(out, s, cut_start, root_end, None, lead, thread_rate(lead, modal), rapid, pass_no, line, 92)
    return out


def plan_g76(s: Point, root_end: Point, taper: float, height: float, first: float, lead: float, setup: G76Setup,
             modal: Modal, rapid: float, line: int) -> list[Segment]:
    """G76's passes from the start point ``s`` to the root ``root_end`` ((z, x)), taper ``taper`` (R, radius:
    the cut's start minus its end), thread height ``height`` and first depth ``first`` (mm, radius)."""
    if height <= 0:
        raise ThreadError("P", "the thread height P must be > 0 (um)")
    if first <= 0:
        raise ThreadError("Q", "the first depth of cut Q must be > 0 (um)")
    if setup.allowance >= height:
        raise ThreadError("P", f"the finishing allowance R{setup.allowance:g} of G76's first block is not below "
                               f"the thread height {height:g} mm: nothing left to rough")
    crest_start = root_end[1] + taper + height
    crest_end = root_end[1] + height
    room = s[1] - max(crest_start, crest_end)
    if room < -EPS:
        raise ThreadError("P", f"the thread height {height:g} mm is larger than the depth available: the start "
                               f"point's X {2 * s[1]:g} stands {s[1] - max(root_end[1] + taper, root_end[1]):g} mm "
                               f"(radius) above the thread's root X {2 * root_end[1]:g}")
    direction = 1.0 if root_end[0] > s[0] else -1.0
    check_thread((s[0], root_end[1] + taper), root_end)
    chamfer = setup.chamfer * lead / 10.0
    length = abs(root_end[0] - s[0])
    if chamfer >= length - EPS:
        raise ThreadError("P", f"the chamfer {setup.chamfer} tenths of the lead ({chamfer:g} mm) is not shorter than "
                               f"the thread ({length:g} mm)")
    flank = math.tan(math.radians(setup.angle) / 2.0)
    rate = thread_rate(lead, modal)
    out: list[Segment] = []
    for n, d in enumerate(g76_depths(height, first, setup.least, setup.allowance, setup.finishing), start=1):
        behind = -direction * (height - d) * flank          # the flank infeed: shallower passes stand behind
        x_start, x_end = crest_start - d, crest_end - d
        z0, z1 = s[0] + behind, root_end[0] + behind
        if chamfer > 0:
            zc = z1 - direction * chamfer
            xc = x_start + (x_end - x_start) * (zc - z0) / (z1 - z0)
            _pass(out, s, (z0, x_start), (zc, xc), (z1, xc + chamfer), lead, rate, rapid, n, line, 76)
        else:
            _pass(out, s, (z0, x_start), (z1, x_end), None, lead, rate, rapid, n, line, 76)
    return out


__all__ = ["MAX_THREAD_PASSES", "NO_MODAL", "TOOL_ANGLES", "G76Setup", "ThreadError", "check_thread", "g76_depths",
           "g76_setup", "plan_g32", "plan_g76", "plan_g92", "thread_rate"]
