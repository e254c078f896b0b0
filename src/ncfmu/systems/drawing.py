"""The part drawn: a DXF drawing's outline as the part the part check judges the part made against (``--drawing``).

A program written by CAM has no G71/G70 profile, so the part check (:mod:`.part`) does not know the part it is
meant to make; a drawing tells it. The DXF (read with ezdxf) holds the part's outline as LINE, ARC, CIRCLE and
LWPOLYLINE entities (with bulges) of its model space, in mm, in the XY plane:

- a lathe's: the upper half section in the part check's (Z, X) plane -- the drawing's X is the machine's Z (0 at
  the program's Z0), its Y the radius; the outline closes along the axis (Y 0), and the part is the region it
  encloses (between the profile and the axis). Toward the chuck, beyond the drawing's smallest Z, the bar is as
  held (not cut, as beyond a G71 profile's end);
- a mill's: the outline in XY (milled outside); closed outlines inside it are holes.

The entities are chained into closed outlines end to end (endpoints within :data:`JOIN_TOLERANCE` are one point),
arcs made polylines at the part check's spacing :data:`~ncfmu.controllers.g7x.ARC_SPACING`; the outline is a
shapely polygon.
Annotations (:data:`ANNOTATIONS`: text, dimensions, leaders, hatches, points) are not the part's outline and are
passed over; every other entity is refused. Refused, with :class:`~ncfmu.errors.DrawingError` (one line: the
file, the entity's handle, the rule): a file ezdxf cannot read, units other than mm ($INSUNITS other than 0
unitless or 4 mm), an entity it does not read (SPLINE, ELLIPSE, ...) or out of the XY plane, an outline that does
not close (where the gap is), branches or crosses itself, several closed outlines of which none holds the others
(which one is the part?), and a lathe's outline below the axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..controllers.g7x import ARC_SPACING
from ..controllers.geometry import Arc, Element, Line, sample
from ..errors import DrawingError

#: Endpoints closer than this (mm) are one point of the outline: 1 um, a tenth of the default tolerance (0.01 mm).
JOIN_TOLERANCE = 1e-3
#: $INSUNITS codes read as mm: 0 (unitless: the drawing is taken to be in mm) and 4 (millimeters).
MM_UNITS = (0, 4)
#: The most points an outline may make (at ARC_SPACING: 20 m of outline): a drawing is a part, not a site plan.
MAX_POINTS = 1_000_000
#: What the outline is made of.
OUTLINE_ENTITIES = ("LINE", "ARC", "CIRCLE", "LWPOLYLINE")
#: Annotations: they describe the part, they are not its outline; passed over.
ANNOTATIONS = ("TEXT", "MTEXT", "DIMENSION", "ARC_DIMENSION", "LARGE_RADIAL_DIMENSION", "LEADER", "MULTILEADER",
               "MLEADER", "TOLERANCE", "HATCH", "POINT", "ATTDEF")


@dataclass(frozen=True)
class Drawing:
    """A drawing read: the part's ``outline`` (a shapely Polygon, holes for inner outlines), the ``path`` it was
    read from and the handles of the entities the outline is made of (in order along it)."""

    path: str
    outline: Any
    handles: tuple[str, ...]


@dataclass(frozen=True)
class _Piece:
    """One entity's (or a polyline segment's) element, with what names it in a message."""

    element: Element
    name: str                             # "ARC 2F", "LWPOLYLINE 30 (segment 2)"
    handle: str


def _reverse(e: Element) -> Element:
    if isinstance(e, Line):
        return Line(e.end, e.start)
    return Arc(e.center, e.radius, e.a0 + e.sweep, -e.sweep)


def _start(e: Element) -> tuple[float, float]:
    return e.start


def _end(e: Element) -> tuple[float, float]:
    return e.end


def _xy(p) -> str:
    return f"({p[0]:.4f}, {p[1]:.4f})"


def read_drawing(path: str | Path) -> Drawing:
    """The part's outline in ``path`` (a DXF file); :class:`DrawingError` when it has none the rules allow."""
    import ezdxf
    from ezdxf.entities import LWPolyline
    name = str(path)
    try:
        doc = ezdxf.readfile(name)
    except OSError as err:
        raise DrawingError(name, "", f"cannot be read: {err.strerror or err}") from None
    except ezdxf.DXFError as err:
        raise DrawingError(name, "", f"is not a DXF file ezdxf reads: {err}") from None
    units = doc.header.get("$INSUNITS", 0)
    if units not in MM_UNITS:
        from ezdxf.units import unit_name
        raise DrawingError(name, "$INSUNITS", f"= {units} ({unit_name(units)}): the drawing must be in mm "
                                              "($INSUNITS 4, or 0 unitless)")
    pieces: list[_Piece] = []
    loops: list[list[_Piece]] = []
    for entity in doc.modelspace():
        kind = entity.dxftype()
        handle = entity.dxf.handle
        if kind in ANNOTATIONS:
            continue
        if kind not in OUTLINE_ENTITIES:
            raise DrawingError(name, f"{kind} {handle}", "cannot be read: the outline is made of "
                               f"{', '.join(OUTLINE_ENTITIES)} (convert it to arcs and lines)")
        found = _pieces(name, entity, kind, handle)
        if kind == "CIRCLE" or (isinstance(entity, LWPolyline) and entity.closed):
            if found:
                loops.append(found)
        else:
            pieces += found
    loops += _chain(name, pieces)
    if not loops:
        raise DrawingError(name, "", f"has no outline (no {', '.join(OUTLINE_ENTITIES)} entities of any length)")
    arcs = sum(p.element.length for loop in loops for p in loop if isinstance(p.element, Arc))
    if arcs / ARC_SPACING + sum(len(loop) for loop in loops) > MAX_POINTS:
        raise DrawingError(name, "", f"has {arcs:.6g} mm of arcs: more than {MAX_POINTS} points at the part "
                                     f"check's {ARC_SPACING:g} mm spacing (is it in mm?)")
    return _outline(name, loops)


def _flat(name: str, entity, what: str) -> int:
    """+1 (or -1, mirrored) when ``entity`` lies in the XY plane (its extrusion +Z or -Z, its elevation 0)."""
    nx, ny, nz = entity.dxf.extrusion
    if abs(nx) > 1e-9 or abs(ny) > 1e-9:
        raise DrawingError(name, what, f"is not in the XY plane (extrusion ({nx:g}, {ny:g}, {nz:g})): "
                                       "the outline is drawn in XY")
    return 1 if nz > 0 else -1


def _finite(name: str, what: str, values: list[float]) -> None:
    bad = [v for v in values if not math.isfinite(v)]
    if bad:
        raise DrawingError(name, what, f"has the coordinate {bad[0]!r}: every coordinate must be a finite number")


def _pieces(name: str, entity, kind: str, handle: str) -> list[_Piece]:
    what = f"{kind} {handle}"
    if kind == "LWPOLYLINE":
        _finite(name, what, [float(v) for point in entity.get_points("xyb") for v in point])
    else:
        _finite(name, what, [float(v) for key in ("start", "end", "center") if entity.dxf.hasattr(key)
                             for v in entity.dxf.get(key)]
                + [float(entity.dxf.get(key)) for key in ("radius", "start_angle", "end_angle")
                   if entity.dxf.hasattr(key)])
    if kind == "LINE":
        s, e = entity.dxf.start, entity.dxf.end
        if abs(s.z) > JOIN_TOLERANCE or abs(e.z) > JOIN_TOLERANCE:
            raise DrawingError(name, what, f"is not in the XY plane (Z {s.z:g} to {e.z:g}): the outline is "
                                           "drawn at Z 0")
        line = Line((s.x, s.y), (e.x, e.y))
        return [_Piece(line, what, handle)] if line.length > JOIN_TOLERANCE else []
    sense = _flat(name, entity, what)
    elevation = entity.dxf.elevation if kind == "LWPOLYLINE" else entity.dxf.center.z
    if abs(elevation) > JOIN_TOLERANCE:
        raise DrawingError(name, what, f"is not in the XY plane (elevation {elevation:g}): the outline is drawn at "
                                       "Z 0")

    def wcs(x: float, y: float) -> tuple[float, float]:
        return (sense * x, y)          # the OCS of the extrusion -Z has its x axis along -X (the arbitrary axis)

    def arc(center: tuple[float, float], radius: float, a0: float, sweep: float) -> Arc:
        c = wcs(*center)
        return Arc(c, radius, a0 if sense > 0 else math.pi - a0, sense * sweep)

    if kind in ("ARC", "CIRCLE"):
        c, r = entity.dxf.center, float(entity.dxf.radius)
        if not r > 0:
            raise DrawingError(name, what, f"has radius {r:g}: must be > 0")
        if kind == "CIRCLE":
            return [_Piece(arc((c.x, c.y), r, 0.0, 2.0 * math.pi), what, handle)]
        a0 = math.radians(entity.dxf.start_angle)
        sweep = math.radians(entity.dxf.end_angle - entity.dxf.start_angle) % (2.0 * math.pi)
        return [_Piece(arc((c.x, c.y), r, a0, sweep or 2.0 * math.pi), what, handle)]
    points = [(float(x), float(y), float(b)) for x, y, b in entity.get_points("xyb")]
    count = len(points) if entity.closed else len(points) - 1
    out: list[_Piece] = []
    for k in range(count):
        (x0, y0, bulge), (x1, y1, _) = points[k], points[(k + 1) % len(points)]
        chord = math.hypot(x1 - x0, y1 - y0)
        if chord <= JOIN_TOLERANCE:
            continue                  # a repeated vertex: no segment
        label = f"{what} (segment {k + 1})"
        if bulge == 0.0:
            out.append(_Piece(Line(wcs(x0, y0), wcs(x1, y1)), label, handle))
            continue
        # the bulge is tan(sweep / 4), + counter-clockwise; the centre lies off the chord's midpoint by
        # chord/2 * cot(sweep/2) to its left (negative: to its right, the arc's far side past a half circle)
        sweep = 4.0 * math.atan(bulge)
        off = 0.5 / math.tan(sweep / 2.0)
        cx = (x0 + x1) / 2.0 - (y1 - y0) * off
        cy = (y0 + y1) / 2.0 + (x1 - x0) * off
        radius = chord / (2.0 * abs(math.sin(sweep / 2.0)))
        out.append(_Piece(arc((cx, cy), radius, math.atan2(y0 - cy, x0 - cx), sweep), label, handle))
    return out


def _cell(p: tuple[float, float]) -> tuple[int, int]:
    return (math.floor(p[0] / JOIN_TOLERANCE), math.floor(p[1] / JOIN_TOLERANCE))


def _chain(name: str, pieces: list[_Piece]) -> list[list[_Piece]]:
    """The open entities chained end to end into closed loops (each piece turned to run along its loop); the ends
    are found through a grid of JOIN_TOLERANCE cells (a drawing of thousands of segments chains in linear time)."""
    grid: dict[tuple[int, int], list[tuple[int, int]]] = {}       # cell -> (piece, 0 its start / 1 its end)
    for i, p in enumerate(pieces):
        for side, q in enumerate((_start(p.element), _end(p.element))):
            grid.setdefault(_cell(q), []).append((i, side))

    def ends_at(q: tuple[float, float]) -> list[tuple[int, int]]:
        cx, cy = _cell(q)
        return [(i, side) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for i, side in grid.get((cx + dx, cy + dy), ())
                if math.dist(q, _end(pieces[i].element) if side else _start(pieces[i].element)) <= JOIN_TOLERANCE]

    used = [False] * len(pieces)
    loops: list[list[_Piece]] = []
    for first in range(len(pieces)):
        if used[first]:
            continue
        used[first] = True
        loop = [pieces[first]]
        while True:
            head, tail = _start(loop[0].element), _end(loop[-1].element)
            meeting = ends_at(tail)
            others = [(i, side) for i, side in meeting if not (i == first and side == 0) and not used[i]]
            if len(meeting) > 2 or len(others) > 1:
                names = sorted({pieces[i].name for i, _ in meeting} | {loop[-1].name})
                raise DrawingError(name, " and ".join(names), f"meet at {_xy(tail)}: the outline branches (one "
                                   "closed outline, each end meeting one other, is the part)")
            if not others and math.dist(head, tail) <= JOIN_TOLERANCE:
                loops.append(loop)              # closed (a full arc alone too)
                break
            if not others:
                near = min(((math.dist(tail, q), p.name, q) for i, p in enumerate(pieces) if not used[i] or i == first
                            for q in (_start(p.element), _end(p.element)) if p is not loop[-1]), default=None)
                hint = f"; the nearest end is {near[1]}'s at {_xy(near[2])}, {near[0]:.4f} mm away" if near else ""
                raise DrawingError(name, loop[-1].name, f"ends at {_xy(tail)} where no other entity starts: the "
                                   f"outline is not closed (a gap; ends within {JOIN_TOLERANCE:g} mm join){hint}")
            i, side = others[0]
            used[i] = True
            e = pieces[i].element
            loop.append(_Piece(e if side == 0 else _reverse(e), pieces[i].name, pieces[i].handle))
    return loops


def _ring(name: str, loop: list[_Piece]):
    """A closed loop as a valid shapely polygon (its arcs at the part check's spacing)."""
    import shapely
    from shapely.geometry import Polygon
    # each element's points but its last (the next one's first is that joint); a joint an arc shares with a line
    # is the line's end as drawn (the arc's, from its angles, is off by rounding: a sliver would cross itself)
    points: list[tuple[float, float]] = []
    for k, piece in enumerate(loop):
        own = sample([piece.element], ARC_SPACING)[:-1]
        before = loop[k - 1].element
        if isinstance(piece.element, Arc) and isinstance(before, Line):
            own[0] = before.end
        points += own
    ring = Polygon(points)
    if not ring.is_valid or ring.area <= 0.0:
        reason = shapely.is_valid_reason(ring)
        raise DrawingError(name, ", ".join(p.name for p in loop), f"make an outline that is not a region "
                           f"({reason}): the outline must not cross or touch itself")
    return ring


def _outline(name: str, loops: list[list[_Piece]]) -> Drawing:
    """The part: the one closed outline, or the one holding every other (those are its holes)."""
    from shapely.geometry import Polygon
    rings = [(_ring(name, loop), loop) for loop in loops]
    rings.sort(key=lambda r: -r[0].area)
    outer, outer_loop = rings[0]
    holes = rings[1:]
    for ring, loop in holes:
        if not outer.contains(ring):
            raise DrawingError(name, f"{outer_loop[0].name} and {loop[0].name}",
                               f"start two closed outlines, neither inside the other (areas {outer.area:.4g} and "
                               f"{ring.area:.4g} mm2): cannot tell which is the part (draw the part alone)")
    for i, (ring, loop) in enumerate(holes):
        for other, other_loop in holes[i + 1:]:
            if ring.intersects(other):
                raise DrawingError(name, f"{loop[0].name} and {other_loop[0].name}",
                                   "start closed outlines inside the part's outline that meet or nest: cannot tell "
                                   "the part's holes (draw each hole once, apart)")
    part = Polygon(outer.exterior.coords, [r.exterior.coords for r, _ in holes])
    handles = tuple(dict.fromkeys(p.handle for _, loop in rings for p in loop))
    return Drawing(name, part, handles)


def half_section(drawing: Drawing) -> None:
    """Refuse a lathe's drawing that reaches below the axis (it is the upper half section)."""
    x0 = drawing.outline.bounds[1]
    if x0 < -JOIN_TOLERANCE:
        raise DrawingError(drawing.path, "", f"reaches Y {x0:.4f}, below the axis: a lathe's drawing is the upper "
                                             "half section (Y the radius >= 0, X the machine's Z)")


def lathe_part(drawing: Drawing, stock: Any) -> Any:
    """The lathe's part drawn, in the part check's (Z, X) plane: the half section's region, and toward the chuck
    -- beyond the drawing's smallest Z -- the ``stock`` as held. Refused when it reaches below the axis."""
    from shapely.geometry import box
    half_section(drawing)
    outline = drawing.outline
    z0 = outline.bounds[0]
    sz0, _, _, sx1 = stock.bounds
    return outline.union(stock.intersection(box(sz0, 0.0, z0, sx1))) if z0 > sz0 else outline
