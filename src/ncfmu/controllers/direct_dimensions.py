"""Fanuc 0i-T's direct drawing dimensions on G01 moves: ``,C`` (a chamfer) and ``,R`` (a corner radius) at the
corner between a G01 block and the next G01, and ``A`` (the line's angle).

``,C c``: the corner is cut by a straight line from c before the corner (on the first move) to c after it (on the
second): c is the distance from the virtual corner along each move, as in Fanuc's figure. ``,R r``: an arc of
radius r tangent to both moves, its ends r tan(turn/2) from the corner. Both shorten the two moves; a chamfer or
radius that would take more than a whole move is refused.

``A``: the angle of the move, degrees counter-clockwise from +Z (with Z to the right and X up, as a lathe
drawing shows the part: A180 runs toward the chuck, A135 toward it and up); the block gives X/U or Z/W, the
other coordinate follows from the angle.

Geometry in the (z, x) plane, X a radius (as :mod:`.lathe_program`).
"""

from __future__ import annotations

import math

from .g7x import EPS
from .geometry import Arc, Element, Line, Point

#: Angles closer than this (rad) to straight on or straight back make no corner.
_STRAIGHT = 1e-9


class DimensionError(ValueError):
    """A direct drawing dimension does not fit its moves (the reader names the block and the word: ``word``)."""

    def __init__(self, word: str, reason: str) -> None:
        super().__init__(reason)
        self.word = word
        self.reason = reason


def _unit(e: Line) -> Point:
    (z0, x0), (z1, x1) = e.start, e.end
    return ((z1 - z0) / e.length, (x1 - x0) / e.length)


def corner(first: Line, second: Line, word: str, size: float) -> tuple[Line | None, Element, Line | None]:
    """The first move shortened, the chamfer (``word`` ",C", ``size`` c) or the corner arc (",R", radius), and
    the second move shortened (None where nothing of a move is left)."""
    if not size > 0:
        raise DimensionError(word, f"{word}{size:g}: a {'chamfer' if word == ',C' else 'corner radius'} is > 0")
    u1, u2 = _unit(first), _unit(second)
    turn = math.atan2(u1[0] * u2[1] - u1[1] * u2[0], u1[0] * u2[0] + u1[1] * u2[1])
    if abs(turn) < _STRAIGHT or abs(abs(turn) - math.pi) < _STRAIGHT:
        raise DimensionError(word, f"{word}{size:g}: the next move runs straight on from (or back along) this one: "
                                   "no corner to " + ("chamfer" if word == ",C" else "round"))
    d = size if word == ",C" else size * math.tan(abs(turn) / 2.0)
    for e, which in ((first, "this"), (second, "the next")):
        if d > e.length + EPS:
            what = (f"the chamfer {size:g}" if word == ",C" else
                    f"the corner radius {size:g} (its ends {d:.4g} mm from the corner)")
            raise DimensionError(word, f"{word}{size:g}: {what} is larger than {which} move ({e.length:.4g} mm)")
    b = first.end
    p1 = (b[0] - d * u1[0], b[1] - d * u1[1])
    p2 = (b[0] + d * u2[0], b[1] + d * u2[1])
    middle: Element
    if word == ",C":
        middle = Line(p1, p2)
    else:
        side = 1.0 if turn > 0 else -1.0                  # the centre on the inside of the turn
        centre = (p1[0] - side * size * u1[1], p1[1] + side * size * u1[0])
        middle = Arc(centre, size, math.atan2(p1[1] - centre[1], p1[0] - centre[0]), turn)
    before = Line(first.start, p1) if math.dist(first.start, p1) > EPS else None
    after = Line(p2, second.end) if math.dist(p2, second.end) > EPS else None
    return before, middle, after


def angled_end(here: Point, angle: float, x: float | None, z: float | None) -> Point:
    """The end of a move from ``here`` at ``angle`` (degrees from +Z, counter-clockwise) reaching X ``x`` (radius)
    or Z ``z`` (one of them given)."""
    a = math.radians(angle)
    dz, dx = math.cos(a), math.sin(a)
    if x is not None:
        if abs(dx) < 1e-12:
            raise DimensionError("A", f"A{angle:g} runs along Z: give Z (or W), X does not fix where it ends")
        t = (x - here[1]) / dx
    else:
        assert z is not None
        if abs(dz) < 1e-12:
            raise DimensionError("A", f"A{angle:g} runs along X: give X (or U), Z does not fix where it ends")
        t = (z - here[0]) / dz
    if t < -EPS:
        raise DimensionError("A", f"A{angle:g}: the end point given lies behind the start along the angle (the "
                                  f"opposite direction is A{(angle + 180.0) % 360.0:g})")
    return (here[0] + t * dz, here[1] + t * dx)


__all__ = ["DimensionError", "angled_end", "corner"]
