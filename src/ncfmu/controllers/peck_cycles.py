"""Fanuc 0i-T's peck cycles (G code system A, mm, X a diameter): G74 end-face peck drilling (and face grooving) and
G75 grooving -- each cycle's moves planned as :class:`.g7x.Segment` s, the seed's sub-cycles (SC1 to the next
plunge, SC2 a peck at the feed, SC3 the retract after it, SC4 back out), and the region it cuts away by its
definition (:meth:`.g7x.PeckCycle.removed`).

Geometry in the (z, x) plane, X a radius (as :mod:`.lathe_program`); S the start point (where the tool stands).

``G74 R(e)`` then ``G74 X(U) Z(W) P(Δi) Q(Δk) R(Δd) F``: from S the tool pecks along Z toward the end Z, each
peck Δk deeper than the one before at the feed (SC2) and back by e at rapid (SC3) before the next (which feeds
through that e again), the last peck to the end Z; there, at rapid, a relief of Δd in X against the direction of
the steps -- on every plunge but the first, whose relief would cut into the groove's side wall -- then Z back to
S's Z (SC4) and X on by Δi (SC1) to the next plunge, the last at the end X; at the end X and Z back to S (SC4).
X omitted (or at S's X) with P0: one plunge -- drilling on the spindle axis (X0, a drill: ``tool[k].drill_diameter``).

``G75 R(e)`` then ``G75 X(U) Z(W) P(Δi) Q(Δk) R(Δd) F``: the same with the axes exchanged -- pecks along X of Δi
toward the end X, retracts e in X, steps of Δk along Z to the end Z, the relief Δd in Z.

P and Q are whole numbers of um as Fanuc writes them (radius values), the first block's R (e) and the second's
(Δd) mm. The first block's e is Fanuc's parameter: G74 and G75 share it, and it stays until the next first block.
"""

from __future__ import annotations

import math

from .g7x import EPS, MAX_SEGMENTS, Segment, Tool
from .geometry import Line, Point
from .thread_cycles import ThreadError as PeckError  # the same record: the word at fault and why

#: A twist drill's point angle (degrees): the cone at a drilled hole's bottom (the part check's drill has it too).
DRILL_POINT = 118.0
#: Far enough for any machine (mm): 'to the outside' in a cycle's region.
OUTSIDE = 1e4
#: Chords per quarter circle of a blade's rounded corner in a groove's region (a 1 mm corner within 1.2 um).
CORNER_CHORDS = 16


def _point(axis: int, along: float, across: float) -> Point:
    """The (z, x) point at ``along`` on the peck's ``axis`` (0: Z, 1: X) and ``across`` on the other."""
    return (along, across) if axis == 0 else (across, along)


def plan_pecks(code: int, s: Point, end: Point, peck: float, step: float, retract: float, relief: float,
               feed: float, line: int) -> list[Segment]:
    """The moves of a G74 (``code`` 74: pecks along Z, steps in X) or G75 (75: pecks along X, steps in Z) from the
    start point ``s`` to ``end`` ((z, x)): pecks of ``peck`` mm, steps of ``step`` mm, the retract ``retract``
    after each peck and the relief ``relief`` at the bottom (mm), ``feed`` mm/s (the program's units)."""
    a = 0 if code == 74 else 1              # the axis the pecks run along
    b = 1 - a                               # the axis the steps run along
    along, across = "ZX"[a], "XZ"[a]
    peck_word, step_word = ("Q", "P") if code == 74 else ("P", "Q")
    depth, span = abs(end[a] - s[a]), abs(end[b] - s[b])
    if depth <= EPS:
        raise PeckError(along, f"G{code}: the end point's {along} is the start point's: nothing to cut along "
                               f"{along}")
    if not peck > 0.0:
        raise PeckError(peck_word, f"{peck_word}0: a peck of 0 um never reaches the end {along}")
    if peck > depth + EPS:
        raise PeckError(peck_word, f"{peck_word}{round(peck * 1000.0)}: a peck of {peck:g} mm is longer than the cut "
                                   f"({depth:g} mm from the start point's {along} to the end {along})")
    if span > EPS and not step > 0.0:
        raise PeckError(step_word, f"{step_word}0: a step of 0 um never reaches the end {across} ({span:g} mm from "
                                   f"the start point's {across})")
    if span <= EPS and step > 0.0:
        raise PeckError(step_word, f"{step_word}{round(step * 1000.0)}: a step in {across} with the end {across} at "
                                   f"the start point's: nothing to step across (give {step_word}0 or the end "
                                   f"{across})")
    if retract < 0.0:
        raise PeckError("R", f"R{retract:g}: the retract after each peck (G{code}'s first block) must be >= 0")
    if relief < 0.0:
        raise PeckError("R", f"R{relief:g}: the relief at the bottom is a distance >= 0 (made against the steps)")
    if relief > 0.0 and span <= EPS:
        raise PeckError("R", f"R{relief:g}: a relief at the bottom is made on the plunges after the first (the "
                             "first's would cut into the side wall): a single plunge takes none, give R0")
    if relief > min(step, span) + EPS:
        raise PeckError("R", f"R{relief:g}: a relief longer than the first step ({min(step, span):g} mm) reaches past "
                             "the first plunge into the side wall")
    pecks = math.ceil(depth / peck - 1e-9)
    plunges = math.ceil(span / step - 1e-9) + 1 if span > EPS else 1
    if plunges * (2 * pecks + 2) > MAX_SEGMENTS:
        raise PeckError(peck_word, f"G{code}: {plunges} plunges of {pecks} pecks plan more than {MAX_SEGMENTS} "
                                   "moves: give longer pecks or steps")
    da = math.copysign(1.0, end[a] - s[a])
    db = math.copysign(1.0, end[b] - s[b]) if span > EPS else 0.0
    out: list[Segment] = []
    here = s

    def go(to: Point, cut: bool, sub: int, pass_no: int) -> None:
        nonlocal here
        if math.dist(here, to) > EPS:
            sigma = s[1] - to[1] if code == 75 else abs(to[1] - s[1])
            out.append(Segment(Line(here, to), feed if cut else 0.0, cut, sub, pass_no, sigma, line, code))
        here = to

    for j in range(plunges):
        at = end[b] if j == plunges - 1 else s[b] + db * j * step   # the plunge's place across
        go(_point(a, s[a], at), False, 1, j + 1)
        for k in range(1, pecks + 1):
            reached = end[a] if k == pecks else s[a] + da * k * peck
            go(_point(a, reached, at), True, 2, j + 1)
            if k < pecks:
                go(_point(a, reached - da * retract, at), False, 3, j + 1)
        if relief > 0.0 and j > 0:
            go(_point(a, end[a], at - db * relief), False, 4, j + 1)
        go(_point(a, s[a], here[b]), False, 4, j + 1)
    go(s, False, 4, plunges)
    return out


def drilled_hole(end_z: float, diameter: float) -> tuple[Point, ...]:
    """The hole a drill of ``diameter`` on the axis, programmed at its point, cuts to ``end_z`` from the outside
    (+Z): its :data:`DRILL_POINT` cone at the bottom, then its diameter."""
    h = diameter / 2.0
    cone = h / math.tan(math.radians(DRILL_POINT / 2.0))
    return ((end_z, 0.0), (end_z + cone, h), (OUTSIDE, h), (OUTSIDE, 0.0))


def _corner(centre: Point, radius: float, start: float) -> list[Point]:
    """A quarter circle of ``radius`` about ``centre`` from the angle ``start`` (radians), counter-clockwise."""
    return [(centre[0] + radius * math.cos(start + i * math.pi / 2 / CORNER_CHORDS),
             centre[1] + radius * math.sin(start + i * math.pi / 2 / CORNER_CHORDS)) for i in range(CORNER_CHORDS + 1)]


def region(code: int, s: Point, end: Point, tool: Tool) -> tuple[Point, ...]:
    """What a G74/G75 from ``s`` to ``end`` cuts away by its definition with ``tool`` (the active offset's row):

    - G74 with a drill (on the axis): the hole (:func:`drilled_hole`);
    - G74 with another tool: the face groove between the start and the end X, from the end Z out, as the
      programmed point sweeps it (the tool table has no face-grooving blade);
    - G75: the groove from the end X out, between the plunges' Z, widened by a blade's ``width`` on the side its
      tip puts the blade (tip 4: toward -Z from the programmed point; else toward +Z, tip 0 as 3), its bottom
      corners rounded by the blade's nose radius; toward the axis (tips 1, 2: inside work) it opens downward.
    """
    if code == 74:
        if tool.drill_diameter > 0.0:
            return drilled_hole(end[0], tool.drill_diameter)
        lo, hi = sorted((s[1], end[1]))
        out = OUTSIDE if end[0] < s[0] else -OUTSIDE
        return ((end[0], lo), (end[0], hi), (out, hi), (out, lo))
    w = tool.width
    lo, hi = sorted((s[0], end[0]))
    if tool.tip == 4:
        lo -= w
    else:
        hi += w
    r = min(tool.nose_radius, w / 2.0)
    x, up = end[1], tool.tip not in (1, 2)
    if not up:
        # inside work (a bore's groove): the blade's body lies below its edge; the groove opens toward the axis
        mirrored = region(75, (s[0], -s[1]), (end[0], -end[1]), Tool(width=w, nose_radius=r, tip=4 if tool.tip == 1
                                                                       else 3))
        return tuple((pz, -px) for pz, px in reversed(mirrored))
    if r <= 0.0:
        return ((lo, x), (hi, x), (hi, OUTSIDE), (lo, OUTSIDE))
    bottom = [*_corner((lo + r, x + r), r, math.pi), *_corner((hi - r, x + r), r, 1.5 * math.pi)]
    return (*bottom, (hi, OUTSIDE), (lo, OUTSIDE))


__all__ = ["DRILL_POINT", "PeckError", "drilled_hole", "plan_pecks", "region"]
