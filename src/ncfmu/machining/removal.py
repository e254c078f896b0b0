"""Material removal on the fly: the tool swept along its actual positions, subtracted from the stock.

Geometry is planar and in the machine's own coordinates (a lathe's half-section ``(z, x)`` with x the radius,
a mill's ``(x, y)``). Polygons and their Boolean operations are shapely's (GEOS).

Per chunk of rows, the rows are cut into *moves* -- runs of one program line and one rapid/feed state. A move's
path (the tool's reference point at every row, joined to the last row of the chunk before) is simplified by
Douglas-Peucker within :data:`RESOLUTION`; the tool swept along each straight piece of it is the convex hull of
the tool at both ends (the tool is convex, the translation straight); their union is the move's swept region.
What of the stock lies inside it is the move's chip: its depth (the largest distance of the chip from the
stock's outline as the move began, also when the move spans chunks) is the radial engagement. Then the chip
leaves the stock.

Crashes, each with the time and program line of the first row where the tool entered:

- a rapid move whose chip is deeper than :data:`TOUCH` ("rapid into the stock");
- a cutting move whose chip is deeper than the tool's ``max_depth`` (plus :data:`TOUCH`);
- a cutting move whose chip is deeper than :data:`TOUCH` taken while the work stands (``standing`` rows: a lathe's
  spindle stopped -- the tool pushed into a bar that does not turn breaks);
- the swept region entering a forbidden region (:class:`Forbidden`: chuck jaws, the far side of the spindle axis,
  a mill part's finished contour) deeper than the region's own threshold.

Accuracy: a circle is a polygon whose chords stay within :data:`RESOLUTION` of it (inscribed), the path is
simplified within :data:`RESOLUTION`, and the stock's outline is simplified within ``RESOLUTION / 5`` after each
cut (so its vertex count stays bounded however often a surface is recut): the part made is exact to about
1 um -- a hundredth of the default tolerance. Memory: the stock, the forbidden regions and at most
:data:`MAX_CRASHES` crash records, whatever the length of the run.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import shapely
from shapely.geometry import Point as ShapelyPoint
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry

#: Geometric resolution of the engine (mm): circles' chords, the path's simplification.
RESOLUTION = 0.0005
#: A chip thinner than this is a touch, not a cut (mm): the servo settling against a surface it just made.
TOUCH = 0.005
#: Chips of a smaller area are not subtracted (mm^2): a recut surface stays as it was.
MIN_AREA = 1e-6
#: Walls of the stock thinner than twice this are no part of the part made (mm): see MaterialRemoval.part.
SLIVER = 0.002
#: What a cut taken while the work stands is called (a lathe's spindle stopped).
STANDING = "cut with the spindle stopped"
#: How many crash records are kept (the count goes on).
MAX_CRASHES = 100
#: Spacing of the points at which a region's depth is measured (mm).
PROBE = 0.05
#: How many of the deepest probes a part's deviation refines (see depth_in).
REFINE = 16

#: The lathe tool's blade above its nose (the insert and its holder in the half-section), mm high.
BLADE = 100.0
#: A turning insert's cutting edges, mm long from its corner (a CNMG 12: 12.9 mm edges, inscribed circle 12.7).
INSERT = 12.0
#: The default turning insert's corner angle (degrees): an 80-degree rhombic insert (ISO C).
INSERT_ANGLE = 80.0
#: Beyond any tool (mm): the extent of the box a tool's outline is clipped to.
FAR_TOOL = 1e4


def _circle_segments(radius: float) -> int:
    """Segments per quarter circle so that the chords stay within RESOLUTION of the circle."""
    if radius <= RESOLUTION:
        return 1
    step = 2.0 * math.acos(1.0 - RESOLUTION / radius)
    return max(1, math.ceil((math.pi / 2) / step))


def _disc(centre: tuple[float, float], radius: float) -> BaseGeometry:
    return ShapelyPoint(centre).buffer(radius, quad_segs=_circle_segments(radius))


def lathe_tool(nose_radius: float, blade: float = BLADE) -> np.ndarray:
    """A turning tool of nose radius ``nose_radius`` whose cutting edges run along Z and X (a square corner):
    the vertices of its convex outline in the half-section ``(z, x)`` around its programmed point at the origin.

    The programmed point is the imaginary tool tip (no nose radius compensation, as the programs are written):
    the nose circle's centre is ``(r, r)``, so the tool's lowest point is at x = 0 and its leftmost at z = 0.
    Above the nose stands the blade, as wide as the nose, ``blade`` mm up. (The part check sweeps the real
    insert, :func:`turning_insert`; this is the engine's plain default.)"""
    r = float(nose_radius)
    if r <= 0.0:
        return np.array([[0.0, 0.0], [0.0, blade]])
    nose = _disc((r, r), r)
    outline = shapely.union_all([nose, shapely.box(0.0, r, 2 * r, r + blade)]).convex_hull
    return np.asarray(outline.exterior.coords)[:-1]


def _hull(parts: list[BaseGeometry]) -> np.ndarray:
    outline = shapely.union_all(parts).convex_hull
    return np.asarray(outline.exterior.coords)[:-1]


def turning_insert(nose_radius: float, angle: float = INSERT_ANGLE, blade: float = BLADE) -> np.ndarray:
    """A turning tool with a rhombic (or triangular, square) insert of corner ``angle`` degrees (0 < angle <= 90)
    and nose radius ``nose_radius``, in its canonical placement (Fanuc's imaginary tip 3: an OD tool cutting
    toward the chuck): the vertices of its convex outline in the half-section ``(z, x)`` around its programmed
    point at the origin (the imaginary tip: the nose circle's centre is ``(r, r)``, its lowest point at x = 0
    and its leftmost at z = 0).

    The tool is set square to the Z axis (a 90-degree holder): its side edge runs along +X from the nose, its
    end edge ``angle`` degrees below that (an 80-degree insert: 10 degrees above the Z axis; a 35-degree one: 55
    degrees -- it may profile down a slope that steep). Why square: a pass toward the chuck ends on a wall
    along X, and the usual retract straight up X (G00 X after G01 Z) leaves it as it is -- a side edge leaning
    past X (a 95-degree holder's) would leave a wedge that very retract cuts at rapid, 0.09 mm a millimetre of
    shoulder, and the check would cry crash at a move every program makes. Both edges are :data:`INSERT` mm
    long, the holder stands on them up to ``blade`` mm above the tip (the tool's height: a boring bar fits its
    hole): what the tool passes under is cut away,
    whatever the direction -- along Z, a plunge in X, a face. ``nose_radius`` 0 is a sharp corner."""
    r = float(nose_radius)
    side = math.pi / 2.0
    end = side - math.radians(float(angle))
    length = INSERT
    c = np.array([r, r])
    # the edges leave the nose circle where they touch it: the end edge below the body, the side edge left of it
    t_end = c + r * np.array([math.sin(end), -math.cos(end)])
    t_side = c + r * np.array([-math.sin(side), math.cos(side)])
    e_end = t_end + length * np.array([math.cos(end), math.sin(end)])
    e_side = t_side + length * np.array([math.cos(side), math.sin(side)])
    ends = np.array([e_end, e_side, (e_end[0], blade), (e_side[0], blade), t_end, t_side])
    parts: list[BaseGeometry] = [shapely.multipoints(ends)]
    if r > 0.0:
        parts.append(_disc((r, r), r))
    # ``blade`` high in all (a boring bar fits its hole)
    outline = shapely.convex_hull(shapely.union_all(parts)).intersection(shapely.box(-FAR_TOOL, -FAR_TOOL, FAR_TOOL,
                                                                                       blade))
    return np.asarray(outline.exterior.coords)[:-1]


def grooving_insert(width: float, nose_radius: float = 0.0, blade: float = BLADE) -> np.ndarray:
    """A grooving (or parting) blade ``width`` mm wide with corners of radius ``nose_radius`` (at most
    ``width / 2``), in its canonical placement (imaginary tip 3: the programmed point is its corner toward the
    chuck, -Z, at its cutting edge): the vertices of its convex outline in ``(z, x)``, the blade ``width`` wide
    along +Z from the programmed point and ``blade`` mm up. A plunge in X cuts a groove of its width; the
    retract along the same path finds nothing more to cut."""
    w, r = float(width), min(float(nose_radius), float(width) / 2.0)
    parts: list[BaseGeometry] = [shapely.multipoints(np.array([[0.0, blade], [w, blade]]))]
    if r > 0.0:
        parts += [_disc((r, r), r), _disc((w - r, r), r)]
    else:
        parts.append(shapely.multipoints(np.array([[0.0, 0.0], [w, 0.0]])))
    return _hull(parts)


def drill(diameter: float, point_angle: float, length: float = BLADE) -> np.ndarray:
    """A twist drill of ``diameter`` mm on the spindle axis pointing -Z, its programmed point the tip of its point
    of ``point_angle`` degrees (the controllers' ``peck_cycles.DRILL_POINT``, whose drilled hole it cuts): the
    vertices of its outline in ``(z, x)`` -- the whole section, both sides of the axis (``length`` mm of it along
    +Z)."""
    h = float(diameter) / 2.0
    cone = h / math.tan(math.radians(point_angle / 2.0))
    return _hull([shapely.multipoints(np.array([[0.0, 0.0], [cone, h], [cone, -h], [cone + length, h],
                                                [cone + length, -h]]))])


#: Fanuc's imaginary tool-nose numbers as the quadrant a tool's body lies in from its programmed point, as the
#: mirror of the canonical placement (tip 3: body toward +Z and +X): (z factor, x factor). The sides (5..8) lie
#: between two corners: a side tip places the body as the corner named (5 as 4, 6 as 2, 7 and 8 as 3).
TIP_MIRROR: dict[int, tuple[float, float]] = {1: (-1.0, -1.0), 2: (1.0, -1.0), 3: (1.0, 1.0), 4: (-1.0, 1.0),
                                              5: (-1.0, 1.0), 6: (1.0, -1.0), 7: (1.0, 1.0), 8: (1.0, 1.0)}


def placed(outline: np.ndarray, tip: int, nose_radius: float = 0.0) -> np.ndarray:
    """A lathe tool ``outline`` in its canonical placement (tip 3) placed as Fanuc's imaginary tool-nose number
    ``tip`` says (1..8; 0 and 9 -- the nose centre programmed -- are the caller's to map to a corner). A corner
    tip (1..4) mirrors it, the nose centre at ``r`` from the programmed point along both axes; a side tip (5..8)
    mirrors it as its corner and moves it so that the programmed point is the nose's extreme point along the
    side (the nose centre at ``r`` from it along that one axis)."""
    fz, fx = TIP_MIRROR[tip]
    out = np.asarray(outline, dtype=float) * np.array([fz, fx])
    if tip >= 5:
        r = float(nose_radius)
        # the canonical centre (r, r) mirrored; a side tip's centre lies at r along the side's axis only
        centre = np.array([fz * r, fx * r])
        wanted = {5: (-r, 0.0), 6: (0.0, -r), 7: (r, 0.0), 8: (0.0, r)}[tip]
        out = out + (np.array(wanted) - centre)
    return out

def mill_cutter(radius: float) -> np.ndarray:
    """The milling cutter in ``(x, y)`` around its centre at the origin: the vertices of its outline. A radius
    below RESOLUTION is taken as RESOLUTION (a point cuts nothing)."""
    disc = _disc((0.0, 0.0), max(abs(float(radius)), RESOLUTION))
    return np.asarray(disc.exterior.coords)[:-1]


@dataclass(frozen=True)
class Forbidden:
    """A region the tool must not enter deeper than ``threshold`` mm; ``what`` names the crash. ``across_axis``:
    the region is the far side of a lathe's spindle axis, which a tool symmetric about the axis (a drill,
    :attr:`Cutter.on_axis`) reaches by its own half there -- not a crash for it."""

    what: str
    region: BaseGeometry
    threshold: float = TOUCH
    across_axis: bool = False


@dataclass(frozen=True)
class Cutter:
    """A tool the engine sweeps: the vertices of its convex outline around its reference point (the axes'
    position: its programmed point less its offsets), (m, 2) -- two vertices, a segment; the deepest chip a
    cutting move may take with it (mm, inf: no limit); ``on_axis``: a tool symmetric about a lathe's spindle
    axis (a drill), which may reach across it."""

    outline: np.ndarray
    max_depth: float = math.inf
    on_axis: bool = False


@dataclass(frozen=True)
class Crash:
    """A crash: when (``t``, s), the program ``line`` (0: none), what, how deep (mm) and where (the first row's
    tool position)."""

    t: float
    line: int
    what: str
    depth_mm: float
    at: tuple[float, float]

    def as_dict(self) -> dict[str, object]:
        return {"t": self.t, "line": self.line, "what": self.what, "depth_mm": self.depth_mm,
                "at": list(self.at)}


@dataclass(frozen=True)
class Move:
    """One move of a chunk: rows ``start..stop`` (the path includes the row before ``start``)."""

    start: int
    stop: int
    rapid: bool
    line: int
    standing: bool = False
    tool: int = 0


def depth_in(piece: BaseGeometry, outline: BaseGeometry, refine: bool = False) -> tuple[float, tuple[float, float]]:
    """The largest distance of ``piece`` from ``outline`` (a boundary), probed at its vertices and every
    :data:`PROBE` mm along its edges; and where.

    ``refine``: then also every :data:`RESOLUTION` mm along the piece's boundary within PROBE of the
    :data:`REFINE` deepest probes (apart from each other). Why: the deepest point of a piece need not be a
    vertex -- where a straight edge of it crosses the ridge of the distance over a convex corner of the outline (a
    lagging cutter cutting a corner off: the deepest point is on the corner's bisector, inside a long edge of
    the swept envelope) the distance peaks with a kink between probes, and PROBE spacing missed up to 6 um there
    (the detuned-servo case: 0.1624 probed against 0.1681 on the bisector)."""
    if piece.is_empty:
        return 0.0, (math.nan, math.nan)
    points = shapely.get_coordinates(shapely.segmentize(piece, PROBE))
    if not len(points):
        return 0.0, (math.nan, math.nan)
    d = shapely.distance(shapely.points(points), outline)
    i = int(np.argmax(d))
    best, at = float(d[i]), (float(points[i, 0]), float(points[i, 1]))
    if not refine:
        return best, at
    picked: list[np.ndarray] = []
    for k in np.argsort(d)[::-1][:50 * REFINE]:
        if all(np.hypot(*(points[k] - q)) > PROBE for q in picked):
            picked.append(points[k])
            if len(picked) == REFINE:
                break
    boundary = piece.boundary
    for q in picked:
        near = boundary.intersection(ShapelyPoint(q).buffer(1.01 * PROBE, quad_segs=4))
        fine = shapely.get_coordinates(shapely.segmentize(near, RESOLUTION))
        if len(fine):
            dd = shapely.distance(shapely.points(fine), outline)
            j = int(np.argmax(dd))
            if dd[j] > best:
                best, at = float(dd[j]), (float(fine[j, 0]), float(fine[j, 1]))
    return best, at


def _areal(geometry: BaseGeometry) -> BaseGeometry:
    """The polygons of ``geometry`` larger than MIN_AREA (a Boolean operation may leave lines and slivers)."""
    parts = [g for g in shapely.get_parts(geometry) if g.geom_type == "Polygon" and g.area > MIN_AREA]
    return shapely.union_all(parts) if parts else Polygon()


class MaterialRemoval:
    """The stock cut by a tool moving along positions fed in chunks (a streamed run's rows).

    Parameters
    ----------
    stock
        the material at the start (a polygon in the machine plane).
    tool
        the vertices of the tool's convex outline around its reference point (the origin), (m, 2); two
        vertices: a segment. The tool of every row whose tool number ``tools`` does not hold.
    forbidden
        regions the tool must not enter (chuck jaws, the axis, a part's finished contour).
    max_depth
        deepest chip a cutting move of ``tool`` may take (mm); ``inf``: no limit.
    tools
        the tools by their number (a lathe's turret station): :meth:`write`'s ``tool`` column picks, row by row,
        the one at work (a tool change ends a move).
    """

    def __init__(self, stock: BaseGeometry, tool: np.ndarray, forbidden: Sequence[Forbidden] = (),
                 max_depth: float = math.inf, tools: Mapping[int, Cutter] | None = None) -> None:
        self.stock: BaseGeometry = stock
        self.initial = stock
        self.default = Cutter(np.asarray(tool, dtype=float).reshape(-1, 2), float(max_depth))
        self.tools = {int(k): replace(c, outline=np.asarray(c.outline, dtype=float).reshape(-1, 2))
                      for k, c in (tools or {}).items()}
        self.forbidden = list(forbidden)
        for f in self.forbidden:
            shapely.prepare(f.region)
        self.crashes: list[Crash] = []
        self.crash_count = 0
        self.removed_area = 0.0
        self.deepest_cut = 0.0                 # the deepest chip of a cutting move so far
        self._last: tuple[float, float, float] | None = None         # (t, u, v) of the last row fed
        # the move that ended the last chunk, and the stock's outline where it began: a move that goes on into the
        # next chunk measures its chip's depth from that outline, not from the face its first part just cut
        self._open: tuple[bool, int, bool, int] | None = None
        self._outline_before: BaseGeometry = stock.boundary
        # the crashes the open move has been reported for (once per move): what -> its index in crashes
        self._reported: dict[str, int | None] = {}

    # -- feeding ---------------------------------------------------------------------------------------
    def write(self, t: np.ndarray, u: np.ndarray, v: np.ndarray, rapid: np.ndarray, line: np.ndarray,
              standing: np.ndarray | None = None, tool: np.ndarray | None = None) -> None:
        """One chunk of rows in time order: time, the tool's two coordinates, whether the move is at rapid, the
        program line, (optional) whether the work stands still (a lathe's spindle stopped: a cut then is a
        crash) and (optional) the number of the tool at work (:attr:`tools`; else the default tool). Rows with
        a position that is not finite are left out."""
        stand = np.zeros(len(t), dtype=bool) if standing is None else np.asarray(standing, dtype=bool)
        tools = np.zeros(len(t), dtype=np.int64) if tool is None else np.asarray(tool).astype(np.int64)
        ok = np.isfinite(u) & np.isfinite(v)
        if not ok.all():
            t, u, v, rapid, line, stand, tools = t[ok], u[ok], v[ok], rapid[ok], line[ok], stand[ok], tools[ok]
        if not len(t):
            return
        rapid = np.asarray(rapid, dtype=bool)
        line = np.asarray(line, dtype=np.int64)
        if self._last is not None:         # the path goes on from the last row of the chunk before
            t0, u0, v0 = self._last
            t = np.concatenate(([t0], t))
            u = np.concatenate(([u0], u))
            v = np.concatenate(([v0], v))
            rapid = np.concatenate((rapid[:1], rapid))
            line = np.concatenate((line[:1], line))
            stand = np.concatenate((stand[:1], stand))
            tools = np.concatenate((tools[:1], tools))
            first = 1
        else:
            first = 0
        self._last = (float(t[-1]), float(u[-1]), float(v[-1]))
        xy = np.column_stack((u, v))
        change = np.flatnonzero((rapid[first + 1:] != rapid[first:-1]) | (line[first + 1:] != line[first:-1])
                                | (stand[first + 1:] != stand[first:-1]) | (tools[first + 1:] != tools[first:-1]))
        bounds = [first, *(change + first + 1).tolist(), len(t)]
        for a, b in zip(bounds, bounds[1:]):
            if b > a:
                move = Move(a, b, bool(rapid[a]), int(line[a]), bool(stand[a]), int(tools[a]))
                key = (move.rapid, move.line, move.standing, move.tool)
                if not (a == first == 1 and self._open == key):
                    self._outline_before = self.stock.boundary
                    self._reported = {}
                self._move(t, xy, move)
                self._open = key

    def cutter(self, number: int) -> Cutter:
        """The tool of that number (the default tool when there is none of it)."""
        return self.tools.get(number, self.default)

    def _swept(self, path: np.ndarray, tool_xy: np.ndarray) -> BaseGeometry:
        """The tool ``tool_xy`` swept along ``path`` ((n, 2) positions)."""
        if len(path) > 2:
            path = shapely.get_coordinates(shapely.LineString(path).simplify(RESOLUTION, preserve_topology=False))
        steps = np.flatnonzero(np.any(np.diff(path, axis=0) != 0.0, axis=1))
        if not len(steps):
            return shapely.convex_hull(shapely.multipoints(tool_xy + path[0]))
        ends = np.stack((path[steps], path[steps + 1]), axis=1)               # (k, 2, 2)
        corners = ends[:, :, None, :] + tool_xy[None, None, :, :]             # (k, 2, m, 2)
        hulls = shapely.convex_hull(shapely.multipoints(corners.reshape(len(steps), -1, 2)))
        return shapely.union_all(hulls)

    def _tools_at(self, xy: np.ndarray, tool_xy: np.ndarray) -> np.ndarray:
        return shapely.convex_hull(shapely.multipoints(xy[:, None, :] + tool_xy[None, :, :]))

    def _first_entry(self, t: np.ndarray, xy: np.ndarray, move: Move, piece: BaseGeometry,
                     depth: float) -> tuple[float, tuple[float, float]]:
        """The time and tool position of the move's first row whose tool reaches into ``piece`` (the chip, or
        what of a forbidden region it entered) by more than TOUCH: when it went in (the row before the move
        included)."""
        a = max(move.start - 1, 0)
        deep = piece.buffer(-min(TOUCH, depth / 4.0)) if depth > 0 else piece
        if deep.is_empty:
            deep = piece
        shapely.prepare(deep)
        hits = np.flatnonzero(shapely.intersects(deep, self._tools_at(xy[a:move.stop],
                                                                       self.cutter(move.tool).outline)))
        i = a + (int(hits[0]) if len(hits) else move.stop - 1 - a)
        return float(t[i]), (float(xy[i, 0]), float(xy[i, 1]))

    def _crash(self, t: np.ndarray, xy: np.ndarray, move: Move, what: str, piece: BaseGeometry,
               depth: float) -> None:
        if what in self._reported:           # a move going on from the chunk before: reported there, deeper now?
            k = self._reported[what]
            if k is not None and depth > self.crashes[k].depth_mm:
                self.crashes[k] = replace(self.crashes[k], depth_mm=depth)
            return
        self.crash_count += 1
        self._reported[what] = None
        if len(self.crashes) < MAX_CRASHES:
            when, at = self._first_entry(t, xy, move, piece, depth)
            self._reported[what] = len(self.crashes)
            self.crashes.append(Crash(when, move.line, what, depth, at))

    def _move(self, t: np.ndarray, xy: np.ndarray, move: Move) -> None:
        path = xy[max(move.start - 1, 0):move.stop]
        cutter = self.cutter(move.tool)
        swept = self._swept(path, cutter.outline)
        for f in self.forbidden:
            if f.across_axis and cutter.on_axis:
                continue
            if shapely.intersects(f.region, swept):
                inside = swept.intersection(f.region)
                depth, _ = depth_in(inside, f.region.boundary)
                if depth > f.threshold:
                    self._crash(t, xy, move, f.what, inside, depth)
        if self.stock.is_empty or not self.stock.intersects(swept):
            return
        # what of the stock the tool passed through: an area (the chip), or a line where a point moved in X only
        inside = self.stock.intersection(swept)
        depth, _ = depth_in(inside, self._outline_before)
        if move.rapid and depth > TOUCH:
            self._crash(t, xy, move, "rapid into the stock", inside, depth)
        elif not move.rapid:
            self.deepest_cut = max(self.deepest_cut, depth)
            if depth > cutter.max_depth + TOUCH:
                self._crash(t, xy, move, f"cut deeper than the tool's max_depth {cutter.max_depth:g} mm", inside,
                            depth)
            if move.standing and depth > TOUCH:
                self._crash(t, xy, move, STANDING, inside, depth)
        chip = _areal(inside)
        if chip.is_empty:
            return
        self.removed_area += chip.area
        self.stock = _areal(self.stock.difference(swept).simplify(RESOLUTION / 5, preserve_topology=True))

    # -- the part ---------------------------------------------------------------------------------------
    def part(self, anchor: BaseGeometry) -> BaseGeometry:
        """The piece of the stock left that holds most of ``anchor`` (the chuck's end of a bar, the finished
        contour of a plate): what is cut off elsewhere is not the part. Walls thinner than ``2 * SLIVER`` are
        not part of it: where two cuts met a hair apart (a pass ending a micrometre short of the face the next
        one cuts), a point tool's path leaves a wall no real tool would; the opening that removes them keeps
        every other edge and corner where it is (square joins)."""
        stock = self.stock.buffer(-SLIVER, join_style="mitre", mitre_limit=1e3)
        stock = _areal(stock.buffer(SLIVER, join_style="mitre", mitre_limit=1e3))
        pieces = list(shapely.get_parts(stock))
        if not pieces:
            return Polygon()
        return max(pieces, key=lambda p: (p.intersection(anchor).area, p.area))


@dataclass(frozen=True)
class Deviation:
    """The part made against the programmed part: the largest excess (material left outside the programmed
    outline, mm) and the largest gouge (material missing inside it, mm), each with where (None: none)."""

    left: float
    left_at: tuple[float, float] | None
    gouge: float
    gouge_at: tuple[float, float] | None


def deviation(made: BaseGeometry, programmed: BaseGeometry) -> Deviation:
    """How far the part ``made`` departs from the ``programmed`` part, both polygons of the same plane."""
    outline = programmed.boundary
    left, left_at = depth_in(_areal(made.difference(programmed)), outline, refine=True)
    gouge, gouge_at = depth_in(_areal(programmed.difference(made)), outline, refine=True)
    return Deviation(left, left_at if left > 0 else None, gouge, gouge_at if gouge > 0 else None)
