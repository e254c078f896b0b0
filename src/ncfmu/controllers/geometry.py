"""Plane geometry of a contour: lines, arcs, their offsets, and cutter compensation.

A contour is a chain of elements (:class:`Line`, :class:`Arc`) in the XY plane, each parametrised by
its path length ``s`` from its start. Cutter compensation (:func:`compensate`) offsets every element
sideways by ``d`` (positive: left of travel) and joins the offsets at each corner:

- tangent corners (the direction turns by less than :data:`TANGENT` rad) need nothing;
- outside corners between two lines turning by at most 90 degrees: the offset lines are extended to
  their intersection, as the seed (GB 1,175,423) does -- the corner moves at most ``|d|*sqrt(2)``;
- every other outside corner (sharper, or with an arc on either side): an arc of radius ``|d|`` around
  the programmed corner is inserted, as LinuxCNC does -- the cutter centre stays exactly ``|d|`` away;
- inside corners: both offsets are trimmed to their intersection; when there is none, or it lies
  beyond an element (the cutter does not fit), :class:`CornerError` names the element;
- finally the whole offset path is measured against the whole contour: where it comes closer than
  ``|d|`` (a spike or a slot narrower than the cutter), :class:`CornerError` names the element.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

from ..errors import NcfmuError

Point = tuple[float, float]

#: Junctions whose direction turns by less than this are tangent (rad).
TANGENT = 1e-9
#: Offset elements whose ends are this close at a nearly tangent junction are joined as they are (mm).
JOIN = 1e-6
#: Lengths below this are zero (mm): an element trimmed to it has vanished.
EPS = 1e-9
TWO_PI = 2.0 * math.pi


class CornerError(NcfmuError):
    """The offset contour cannot be built at element ``index`` (0-based), for ``reason``; ``other`` is the
    element it collides with, if any (:meth:`describe` names it in the caller's terms)."""

    def __init__(self, index: int, reason: str, other: int | None = None):
        self.index, self.reason, self.other = index, reason, other
        super().__init__(f"element {index}: {reason.replace('{other}', f'element {other}')}")

    def describe(self, names: Sequence[str]) -> str:
        """The reason, with the colliding element called ``names[other]``."""
        return self.reason.replace("{other}", names[self.other] if self.other is not None else "")


@dataclass(frozen=True)
class Line:
    start: Point
    end: Point

    @cached_property
    def length(self) -> float:
        return math.hypot(self.end[0] - self.start[0], self.end[1] - self.start[1])

    @cached_property
    def unit(self) -> Point:
        length = self.length
        if length == 0.0:
            return (0.0, 0.0)
        return ((self.end[0] - self.start[0]) / length, (self.end[1] - self.start[1]) / length)

    def point(self, s: float) -> Point:
        ux, uy = self.unit
        return (self.start[0] + ux * s, self.start[1] + uy * s)

    def tangent(self, s: float) -> Point:
        return self.unit

    def offset(self, d: float) -> Line:
        ux, uy = self.unit
        return Line((self.start[0] - uy * d, self.start[1] + ux * d), (self.end[0] - uy * d, self.end[1] + ux * d))

    def param(self, p: Point) -> float:
        """Path length from the start to the foot of ``p`` (may be negative or beyond the end)."""
        ux, uy = self.unit
        return (p[0] - self.start[0]) * ux + (p[1] - self.start[1]) * uy

    def sub(self, s0: float, s1: float) -> Line:
        return Line(self.point(s0), self.point(s1))


@dataclass(frozen=True)
class Arc:
    """Circular arc: ``center``, ``radius``, start angle ``a0`` (rad), signed ``sweep`` (+ counter-clockwise)."""

    center: Point
    radius: float
    a0: float
    sweep: float

    @property
    def ccw(self) -> bool:
        return self.sweep > 0

    @cached_property
    def length(self) -> float:
        return self.radius * abs(self.sweep)

    @property
    def start(self) -> Point:
        return self._at(self.a0)

    @property
    def end(self) -> Point:
        return self._at(self.a0 + self.sweep)

    def _at(self, a: float) -> Point:
        return (self.center[0] + self.radius * math.cos(a), self.center[1] + self.radius * math.sin(a))

    def angle(self, s: float) -> float:
        return self.a0 + math.copysign(s / self.radius, self.sweep)

    def point(self, s: float) -> Point:
        return self._at(self.angle(s))

    def tangent(self, s: float) -> Point:
        a = self.angle(s)
        sign = 1.0 if self.sweep > 0 else -1.0
        return (-sign * math.sin(a), sign * math.cos(a))

    def offset(self, d: float) -> Arc:
        """Left of travel is toward the centre on a counter-clockwise arc: the radius shrinks by ``d``."""
        return Arc(self.center, self.radius - (d if self.sweep > 0 else -d), self.a0, self.sweep)

    def param(self, p: Point) -> float:
        """Path length from the start, in the arc's sense, to the direction of ``p``: in [-EPS, 2*pi*R - EPS)."""
        a = math.atan2(p[1] - self.center[1], p[0] - self.center[0])
        turn = (a - self.a0) if self.sweep > 0 else (self.a0 - a)
        s = (turn % TWO_PI) * self.radius
        return s - TWO_PI * self.radius if s > TWO_PI * self.radius - EPS else s

    def sub(self, s0: float, s1: float) -> Arc:
        return Arc(self.center, self.radius, self.angle(s0), math.copysign((s1 - s0) / self.radius, self.sweep))


Element = Line | Arc


def arc_through(start: Point, end: Point, center: Point, ccw: bool, max_shift: float) -> Arc:
    """The arc from ``start`` around ``center`` to ``end`` (a full circle when they coincide), for a centre whose
    radii to start and end differ a little (the caller bounds the difference).

    When moving the centre onto the chord's bisector (to the nearest point) shifts it by at most ``max_shift``,
    the arc runs exactly through both points and stays within ``max_shift`` of the programmed circle. Else (a
    short chord: a tiny arc or a nearly full circle) the centre and the radius to the start are kept -- the arc
    leaves ``start`` in the programmed direction -- and it ends on its circle toward ``end``, at most the radius
    difference from it.
    """
    cx, cy = center
    mx, my = (start[0] + end[0]) / 2, (start[1] + end[1]) / 2
    chord = math.hypot(end[0] - start[0], end[1] - start[1])
    if chord > 0.0:
        nx, ny = -(end[1] - start[1]) / chord, (end[0] - start[0]) / chord
        along = (cx - mx) * nx + (cy - my) * ny
        bx, by = mx + along * nx, my + along * ny
        if math.hypot(bx - cx, by - cy) <= max_shift:
            cx, cy = bx, by
    radius = math.hypot(start[0] - cx, start[1] - cy)
    a0 = math.atan2(start[1] - cy, start[0] - cx)
    a1 = math.atan2(end[1] - cy, end[0] - cx)
    if ccw:
        sweep = (a1 - a0) % TWO_PI
        sweep = TWO_PI if sweep < 1e-12 else sweep
    else:
        sweep = -((a0 - a1) % TWO_PI)
        sweep = -TWO_PI if sweep > -1e-12 else sweep
    return Arc((cx, cy), radius, a0, sweep)


def sample(elements: list[Element], spacing: float) -> list[Point]:
    """Points along ``elements`` at most ``spacing`` apart (for plots), both ends of each element included."""
    points: list[Point] = []
    for e in elements:
        pieces = max(1, math.ceil(e.length / spacing)) if isinstance(e, Arc) else 1
        points += [e.point(e.length * i / pieces) for i in range(0 if not points else 1, pieces + 1)]
    return points


def turn_angle(a: Point, b: Point) -> float:
    """Signed angle from direction ``a`` to direction ``b`` (+: left turn), in (-pi, pi]."""
    return math.atan2(a[0] * b[1] - a[1] * b[0], a[0] * b[0] + a[1] * b[1])


# -- intersections of the underlying infinite line / full circle --------------------------------------
def _line_line(a: Line, b: Line) -> list[Point]:
    (ux, uy), (vx, vy) = a.unit, b.unit
    den = ux * vy - uy * vx
    if abs(den) < 1e-15:
        return []
    wx, wy = b.start[0] - a.start[0], b.start[1] - a.start[1]
    t = (wx * vy - wy * vx) / den
    return [a.point(t)]


def _line_circle(a: Line, c: Arc) -> list[Point]:
    foot = a.param(c.center)
    fx, fy = a.point(foot)
    off = math.hypot(fx - c.center[0], fy - c.center[1])
    h2 = (c.radius - off) * (c.radius + off)          # factored: no cancellation when the line nearly touches
    if h2 < -1e-12 * c.radius ** 2:
        return []
    h = math.sqrt(max(h2, 0.0))
    return [a.point(foot - h), a.point(foot + h)]


def _circle_circle(a: Arc, b: Arc) -> list[Point]:
    dx, dy = b.center[0] - a.center[0], b.center[1] - a.center[1]
    dist = math.hypot(dx, dy)
    if dist < 1e-15:
        return []
    along = (dist * dist + (a.radius - b.radius) * (a.radius + b.radius)) / (2 * dist)
    h2 = (a.radius - along) * (a.radius + along)      # factored: no cancellation when the circles nearly touch
    if h2 < -1e-12 * a.radius ** 2:
        return []
    h = math.sqrt(max(h2, 0.0))
    mx, my = a.center[0] + along * dx / dist, a.center[1] + along * dy / dist
    return [(mx - h * dy / dist, my + h * dx / dist), (mx + h * dy / dist, my - h * dx / dist)]


def intersections(a: Element, b: Element) -> list[Point]:
    if isinstance(a, Line) and isinstance(b, Line):
        return _line_line(a, b)
    if isinstance(a, Line):
        return _line_circle(a, b)  # type: ignore[arg-type]
    if isinstance(b, Line):
        return _line_circle(b, a)
    return _circle_circle(a, b)


# -- distances -------------------------------------------------------------------------------------------
def point_distance(p: Point, e: Element) -> float:
    """Distance of ``p`` from the element (a segment or an arc, not the infinite line or full circle)."""
    if isinstance(e, Line):
        length = e.length
        s = min(max(e.param(p), 0.0), length)
        q = e.point(s)
        return math.hypot(p[0] - q[0], p[1] - q[1])
    if e.param(p) <= e.length:
        return abs(math.hypot(p[0] - e.center[0], p[1] - e.center[1]) - e.radius)
    return min(math.dist(p, e.start), math.dist(p, e.end))


def _on(e: Element, p: Point) -> bool:
    """``p`` (a point of the element's line or circle) lies within the element."""
    s = e.param(p)
    return -EPS <= s <= e.length + EPS


def min_distance(a: Element, b: Element) -> float:
    """Least distance between two elements: 0 where they cross, else at an end point or where the line
    between them is normal to both (for an arc: along the radius toward the other element)."""
    if any(_on(a, p) and _on(b, p) for p in intersections(a, b)):
        return 0.0
    candidates = [point_distance(a.start, b), point_distance(a.end, b),
                  point_distance(b.start, a), point_distance(b.end, a)]
    for arc, other in ((a, b), (b, a)):
        if not isinstance(arc, Arc):
            continue
        if isinstance(other, Line):
            ux, uy = other.unit
            towards = [(-uy, ux), (uy, -ux)]                 # radii normal to the line
        else:
            dx, dy = other.center[0] - arc.center[0], other.center[1] - arc.center[1]
            dist = math.hypot(dx, dy)
            towards = [(dx / dist, dy / dist), (-dx / dist, -dy / dist)] if dist > 0 else []
        for nx, ny in towards:
            p = (arc.center[0] + arc.radius * nx, arc.center[1] + arc.radius * ny)
            if _on(arc, p):
                candidates.append(point_distance(p, other))
    return min(candidates)


def bounds(e: Element) -> tuple[float, float, float, float]:
    """(xmin, ymin, xmax, ymax) of the element."""
    xs, ys = [e.start[0], e.end[0]], [e.start[1], e.end[1]]
    if isinstance(e, Arc):
        for k in range(4):                                   # the axis extremes the arc passes
            p = (e.center[0] + e.radius * math.cos(k * math.pi / 2), e.center[1] + e.radius * math.sin(k * math.pi / 2))
            if _on(e, p):
                xs.append(p[0])
                ys.append(p[1])
    return min(xs), min(ys), max(xs), max(ys)


def _ring_gap(arc: Arc, other: Element) -> float:
    """A lower bound of the distance between ``other`` and the arc's full circle: how far ``other`` stays out of
    the ring (cheap; it rules out concentric and distant pairs without measuring them)."""
    c = arc.center
    if isinstance(other, Line):
        near = point_distance(c, other)
        far = max(math.dist(c, other.start), math.dist(c, other.end))
    else:
        centres = math.dist(c, other.center)
        near, far = max(0.0, centres - other.radius), centres + other.radius
    return max(0.0, near - arc.radius, arc.radius - far)


def closest_approach(pieces: list[tuple[Element, int]], contour: list[Element],
                     limit: float) -> tuple[int, int, float] | None:
    """The first (piece's element, contour element, distance) closer than ``limit``, else None.

    Only pairs whose bounding boxes come within ``limit`` are measured (sorted by X, so a long program
    is not measured pair by pair)."""
    boxes = sorted((bounds(e)[0], k, bounds(e)) for k, e in enumerate(contour))
    lows = [b[0] for b in boxes]
    for piece, owner in pieces:
        x0, y0, x1, y1 = bounds(piece)
        for _, k, (_, ey0, ex1, ey1) in boxes[:bisect.bisect_right(lows, x1 + limit)]:
            if ex1 < x0 - limit or ey1 < y0 - limit or ey0 > y1 + limit:
                continue
            element = contour[k]
            if any(isinstance(arc, Arc) and _ring_gap(arc, other) >= limit
                   for arc, other in ((piece, element), (element, piece))):
                continue
            dist = min_distance(piece, element)
            if dist < limit:
                return owner, k, dist
    return None


# -- cutter compensation -------------------------------------------------------------------------------
def compensate(elements: list[Element], d: float, closed: bool,
               round_corners: bool = False) -> list[tuple[Element, int]]:
    """The cutter-centre path of ``elements`` offset by ``d`` (+ left of travel), with its corners joined.

    ``round_corners``: every outside corner gets the arc of radius ``|d|`` (a lathe's tool nose: its circle
    touches the programmed corner all the way round, where the extended lines would leave it off the contour).

    Returns ``(element, index)`` pairs: ``index`` is the programmed element the piece belongs to (an
    inserted corner arc belongs to the element after the corner; the closing corner of a ``closed``
    chain comes last and belongs to the last element).

    Raises
    ------
    CornerError
        an arc whose offset radius is not positive, an inside corner the cutter cannot reach, or an
        element that the corrections on both its ends make vanish or run backwards.
    """
    n = len(elements)
    if d == 0.0:
        return [(e, k) for k, e in enumerate(elements)]
    offsets: list[Element] = []
    for k, e in enumerate(elements):
        o = e.offset(d)
        if isinstance(o, Arc) and o.radius <= EPS:
            assert isinstance(e, Arc)
            raise CornerError(k, f"arc of radius {e.radius:g} mm offset by {abs(d):g} mm toward its centre: "
                                 f"R - r = {o.radius:g} mm <= 0, the cutter does not fit")
        offsets.append(o)
    trim = [[0.0, o.length] for o in offsets]        # the part of each offset element that is kept
    corner_arcs: dict[int, Arc] = {}                  # junction k (after element k) -> inserted arc
    junctions = range(n if closed else n - 1)
    for k in junctions:
        j = (k + 1) % n
        a, b, oa, ob = elements[k], elements[j], offsets[k], offsets[j]
        turn = turn_angle(a.tangent(a.length), b.tangent(0.0))
        if abs(turn) <= TANGENT or (abs(turn) < 1e-3 and math.dist(oa.point(oa.length), ob.start) <= JOIN):
            # tangent, or so nearly (a program's rounded coordinates) that the offsets meet within JOIN: an
            # intersection of two nearly parallel elements would only amplify the rounding
            continue
        corner = a.end if isinstance(a, Line) else b.start
        if abs(turn) >= math.pi - TANGENT:
            turn = -math.copysign(math.pi, d)        # a reversal: around the tip, whichever side
        if turn * d < 0:                             # outside corner
            if (not round_corners and isinstance(a, Line) and isinstance(b, Line)
                    and abs(turn) <= math.pi / 2 + 1e-12):
                (p,) = _line_line(oa, ob)            # type: ignore[arg-type]
                trim[k][1], trim[j][0] = oa.param(p), ob.param(p)
            else:
                start = oa.point(oa.length)
                a0 = math.atan2(start[1] - corner[1], start[0] - corner[0])
                corner_arcs[k] = Arc(corner, abs(d), a0, turn)
            continue
        # inside corner: trim both to the intersection nearest the corner (back along a, forward along b)
        best = None
        for p in intersections(oa, ob):
            pa, pb = oa.param(p), ob.param(p)
            if isinstance(oa, Arc) and pa < trim[k][0] - EPS:
                pa += TWO_PI * oa.radius                      # an arc's param wraps; the end side counts
            back, forward = trim[k][1] - pa, pb - trim[j][0]
            if back < -1e-7 or forward < -1e-7:
                continue
            if best is None or back + forward < best[0]:
                best = (back + forward, pa, pb)
        if best is None:
            raise CornerError(j, f"inside corner of {math.degrees(abs(turn)):.4g} deg: the offset elements do "
                                 f"not meet, a cutter offset by {abs(d):g} mm would gouge the contour")
        trim[k][1], trim[j][0] = best[1], best[2]
    for k in range(n):
        s0, s1 = trim[k]
        if s1 - s0 <= EPS:
            raise CornerError(k, f"the correction {abs(d):g} mm makes this element "
                                 f"({'vanish' if abs(s1 - s0) <= EPS else 'run backwards'}): the offset path "
                                 "would loop; use a smaller correction or a longer element")
        if isinstance(offsets[k], Arc) and s1 - s0 > offsets[k].length + 1e-7:
            raise CornerError(k, f"the correction {abs(d):g} mm trims this arc past its own end")
    out: list[tuple[Element, int]] = []
    for k in range(n):
        if k - 1 in corner_arcs:
            out.append((corner_arcs[k - 1], k))
        out.append((offsets[k].sub(*trim[k]), k))
    if closed and n - 1 in corner_arcs:
        out.append((corner_arcs[n - 1], n - 1))
    # the whole cutter-centre path keeps |d| from the whole contour: where the contour is narrower than the
    # cutter (a thin spike, a slot, two features close together) the offset of one element comes too close
    # to another, and cutting it would gouge
    too_close = closest_approach(out, elements, abs(d) * (1.0 - 1e-9) - 1e-9)
    if too_close is not None:
        k, other, dist = too_close
        near = "crosses {other}" if dist == 0.0 else f"comes within {dist:.4g} mm of {{other}}"
        raise CornerError(k, f"its offset {near} (the correction is {abs(d):g} mm): the contour is narrower "
                             "than the cutter there, cutting it would gouge", other)
    return out


# Here, not in contour.py: a state carries these, and fmi/state.py checks a dataclass's fields by their declared
# types -- which mypyc erases in a compiled module's dataclasses (``element: Element`` reads ``type`` there).
@dataclass(frozen=True)
class ToolMove:
    """One element of the cutter-centre path (the contour interpolator's) and how it is run."""

    element: Element
    rapid: bool          # at ``approach_feed`` (G00, the approach), not ``feed``
    feed: float          # mm/s
    label: int           # the ``segment`` output: segment number (point path) or program line
