"""Fanuc 0i-T's single cycles (G code system A, mm, X a diameter): G90 the outer/inner diameter turning cycle and
G94 the facing cycle -- each block one pass of four moves, planned as :class:`.g7x.Segment` s, the seed's
sub-cycles (SC1 in at rapid, SC2 the cut, SC3 out at the feed, SC4 back to the start point at rapid).

Geometry in the (z, x) plane, X a radius (as :mod:`.lathe_program`); S the start point (where the tool stands).

G90 X Z R F: SC1 X from S to the cut's start X/2 + R (R, radius: the cut's start X less its end's -- a taper),
SC2 the cut from S's Z to (Z, X/2), SC3 X back out to S's X at the feed, SC4 Z back to S's Z. Outside (X below
S's X) or inside (above it: boring).

G94 X Z R F: SC1 Z from S to the cut's start Z + R (R: the cut's start Z less its end's -- a taper face), SC2 the
face cut in X from S's X to (Z, X/2), SC3 Z back out to S's Z at the feed, SC4 X back to S's X.

Both are modal (Fanuc's group 01): a following block with X/U or Z/W alone is the next pass, the words it does not
give (Z or X, R, F) as before; G00-G03 (or G32, G92) end them.
"""

from __future__ import annotations

from .g7x import EPS, Segment
from .geometry import Line, Point
from .thread_cycles import ThreadError as CycleError  # the same record: the word at fault and why


def plan_single(code: int, s: Point, end: Point, taper: float, feed: float, pass_no: int,
                line: int) -> list[Segment]:
    """One G90 (``code`` 90) or G94 (94) pass from the start point ``s`` to ``end`` ((z, x)), the taper ``taper``
    (R: radius for G90, along Z for G94), ``feed`` mm/s (the program's units: under G99 per rev/min)."""
    if abs(end[0] - s[0]) <= EPS or abs(end[1] - s[1]) <= EPS:
        axis = "Z" if abs(end[0] - s[0]) <= EPS else "X"
        raise CycleError(axis, f"G{code}: the end point's {axis} is the start point's: the cycle needs a cut in X "
                               "and in Z from the start point")
    if code == 90:
        cut_start = (s[0], end[1] + taper)
        beyond = (cut_start[1] - s[1]) * (end[1] - s[1])
    else:
        cut_start = (end[0] + taper, s[1])
        beyond = (cut_start[0] - s[0]) * (end[0] - s[0])
    if taper and beyond <= EPS * EPS:
        raise CycleError("R", f"R{taper:g}: the cut's start would lie at or beyond the start point "
                              f"({'X' if code == 90 else 'Z'}): |R| must be less than the cut's depth from it")
    # SC3 ends straight out from the cut's end at S's X (G90), or straight back from the face at S's Z (G94)
    corner = (end[0], s[1]) if code == 90 else (s[0], end[1])
    sigma = s[1] - end[1]
    moves = ((s, cut_start, False, 1), (cut_start, end, True, 2), (end, corner, True, 3), (corner, s, False, 4))
    return [Segment(Line(a, b), feed if cut else 0.0, cut, sub, pass_no, sigma, line, code)
            for a, b, cut, sub in moves if a != b]


__all__ = ["CycleError", "plan_single"]
