"""The lathe's G7x cycles over the one move record: G71 stock removal and G70 finishing, planned as the
seed's sub-cycles (US 4,017,723: SC1 infeed, SC2 cut, SC3 retract, SC4 return) -- LinuxCNC's interp_g7x.

Geometry in the (z, x) plane as :mod:`.lathe_program` reads it.

The profile N<P>..N<Q>: its first block moves in X only, from the cycle's start point S to the profile's
start A (Fanuc's form); the rest runs toward the chuck (Z never increases), inside the stock (at most S's X,
never below the axis). The stock is what lies between S's X and the profile, behind S's Z (S stands in front
of it), up to the profile's end; beyond the profile's end a wall at its Z is left standing.

G71 roughing: the allowances shift the profile by U in X and W in Z (Fanuc's meaning) -- the rough
boundary. Levels at X = S.x - k*U while above the boundary's lowest point; at each level one pass per Z range
where the boundary lies below the level: one range for a monotone profile (Fanuc's type I), one more for each
pocket or undercut the level reaches (type II: X falls along -Z). Each pass is SC1 (reach the range's start:
at S's Z a rapid infeed; into a pocket up over the material left, along Z, and down at the feed, at most U
into it), SC2 (cut in -Z at the feed to the range's end), SC3 (retract by R in +X), SC4 (rapid return in +Z to
the range's start). Then one more pass along the rough boundary (SC1 at the feed, SC2 along it, SC3 up clear
of it, SC4 back to S's Z), so the stock left is the allowance everywhere, and a rapid move back to S. Rapid
moves pass only through air. With a pocket, W must be 0: a shift in Z would move the pocket's near wall into
the part (on a vertical wall in a pocket the finishing allowance is then 0, as with Fanuc's type II). A
monotone profile shifted by (W, U) with W >= 0 is never below the profile plus U at any Z.

G70 finishing: SC1 the profile's first block (from where the tool stands), SC2 the profile as programmed
(G70's F when given, else each block's own feed), SC3 +X clear of the start point's X, SC4 +Z to its Z.
After a cycle whose profile follows it, the program goes on after N<Q>, from the start point, in the modes
in force before the profile.
"""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from dataclasses import dataclass, replace

from ..errors import ProgramError
from .gcode import Move
from .geometry import Arc, CornerError, Element, Line, Point, bounds, sample
from .mypyc_compat import mypyc_attr
from .nose import Nose
from .nose import translated as shifted

#: More planned moves than this are refused: one part, a few hundred passes at most.
MAX_SEGMENTS = 20_000
#: Points closer than this are one point (mm).
EPS = 1e-9
#: Geometric tolerance of the profile checks (monotone, inside the stock), mm.
TOL = 1e-6
#: Far enough for any machine (mm): the open side of a region a cycle cuts away ("to the outside").
FAR = 1e4
#: Spacing of the points along a region's arcs (mm): chords within 0.1 um of an arc of 1 mm radius.
ARC_SPACING = 0.02


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Tool:
    """A row of the tool table: where the tool's tip stands from the axes' reference (radius, Z), its nose."""

    x_offset: float = 0.0       # mm, radius: the axes stand at the programmed point + the offset
    z_offset: float = 0.0       # mm
    nose_radius: float = 0.0    # mm
    tip: int = 0                # Fanuc's imaginary tool-nose number 0..9
    max_depth: float = 0.0      # mm, the deepest cut the insert takes (0: not given)
    # the tool's shape (the part check sweeps it; the planner does not read it, but G74/G75 check it)
    insert_angle: float = 80.0  # deg, the turning insert's corner angle
    width: float = 0.0          # mm, a grooving or parting blade's width along Z (0: not one)
    drill_diameter: float = 0.0  # mm, a drill's on the spindle axis, programmed at its point (0: not one)


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Modal:
    """What a lathe program sets besides positions, as it runs with a planned move: the tool and its offset, the
    spindle, the feed mode, the coolant."""

    tool: int = 0                        # turret station of T<tool><offset> (0: none)
    offset: Point = (0.0, 0.0)           # the active work + tool offset (z, x radius): axes = programmed point + it
    spindle: int = 0                     # +1 M03, -1 M04, 0 M05
    s: float = 0.0                       # S: rev/min (G97) or the surface speed in m/min (G96)
    css: bool = False                    # G96 constant surface speed
    s_max: float = 0.0                   # G50 S: the highest rev/min under G96
    per_rev: bool = False                # G99: a feed's rate is mm/s per rev/min of the actual spindle speed
    coolant: bool = False                # M08 / M09

    def rpm(self, x: float) -> float:
        """The spindle speed commanded with the tool at radius ``x`` (programmed): S under G97; under G96
        1000 v / (pi D), D = 2|x|, at most G50 S. 0 with the spindle stopped."""
        if not self.spindle:
            return 0.0
        if not self.css:
            return self.s
        d = 2.0 * abs(x)
        return self.s_max if d <= 0.0 else min(self.s_max, 1000.0 * self.s / (math.pi * d))


NO_MODAL = Modal()


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Segment:
    """One planned move of the program and what the sequencer reports while it runs."""

    element: Element        # in the (z, x) plane
    rate: float             # mm/s
    feed: bool              # a cutting feed (the override applies), else rapid
    subcycle: int           # 0 outside a pass, 1..4 the seed's sub-cycles
    pass_no: int            # pass of the cycle (0 outside a cycle)
    sigma_x: float          # depth of the pass below the cycle's start point, mm
    line: int               # program line being executed (1-based)
    cycle: int              # 71, 70, 76, 92, 32 (a G32 thread), 90, 94 or 0
    dwell: float = 0.0      # s to wait at the move's end (G04)
    stop: int = 0           # at the move's end wait for START: 1 always (M00), 2 with the optional stop on (M01)
    modal: Modal = NO_MODAL
    lead: float = 0.0       # a thread (G32/G92/G76): mm of Z per spindle revolution, Z following the spindle
    continues: bool = False  # a thread continuing the one before it (no new wait for the one-revolution marker)


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Profile:
    """The profile N<P>..N<Q>: the first block's move from the start point, then the part's outline."""

    p: int
    q: int
    lead: Move              # the N<P> block: S -> A, in X only
    blocks: tuple[Move, ...]
    pocket: int = 0                 # the line where X first falls along -Z (type II), 0: monotone (type I)
    front: Element | None = None    # a first block moving in Z too: the profile's X from the start point's Z on
    inside: bool = False            # an inside (bore) profile: X rises from the start point (planned mirrored)

    @property
    def elements(self) -> list[Element]:
        return [b.element for b in self.blocks]

    @property
    def outline(self) -> list[Element]:
        """What G71 roughs to: the elements, after the front piece of a first block that moved in Z too."""
        return ([self.front] if self.front is not None else []) + self.elements

    def removed(self) -> tuple[Point, ...]:
        """What the profile's cycles cut away by their definition, a simple polygon of (Z, radius) points: all
        above the profile (outside), or below it toward the axis (inside, a bore: down to the hole)."""
        outline = sample(self.elements, ARC_SPACING)
        (za, _), (ze, _) = outline[0], outline[-1]
        far = -FAR if self.inside else FAR
        return tuple(outline) + ((ze, far), (za, far))


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Rough:
    """A G71 cycle: from ``start`` ((z, x)), depth ``depth`` and retract ``retract`` (radius), allowances
    ``u`` (radius) and ``w``, ``feed`` mm/s."""

    line: int
    start: Point
    profile: Profile
    depth: float
    retract: float
    u: float
    w: float
    feed: float

    def removed(self) -> tuple[Point, ...]:
        """The region the cycle cuts away by its definition: its profile's (the part's outline, not the passes)."""
        return self.profile.removed()


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Finish:
    """A G70 cycle from ``start`` ((z, x)) along ``profile`` (``feed`` mm/s overrides the blocks' own; 0: none),
    with the tool-nose radius compensation ``nose`` (G41/G42) or none (G40)."""

    line: int
    start: Point
    profile: Profile
    feed: float
    nose: Nose | None = None

    def removed(self) -> tuple[Point, ...]:
        """The region the cycle cuts away by its definition: its profile's (the part's outline, not the passes)."""
        return self.profile.removed()



@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class State:
    """From here on the program runs with ``modal`` (T, S, M03/M04/M05, M08/M09, G96/G97, G98/G99, G50 S)."""

    line: int
    modal: Modal
    power_on: bool = False  # the state the program starts in: its offset is where the axes already are


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Dwell:
    line: int
    seconds: float          # G04


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Stop:
    line: int
    optional: bool          # M01 (else M00)


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Home:
    """G28: at the rapid rate to the intermediate point ``via`` (programmed), then to the machine reference
    ``home`` (axes), each as (z, x) with None where the block names no such axis (it stays)."""

    line: int
    via: Point
    home: tuple[float | None, float | None]


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Thread:
    """A thread: G32's cut, a G92 pass or a whole G76 (:mod:`.thread_cycles`), its moves planned in the program's
    coordinates; the tool ends at ``end``."""

    line: int
    code: int                       # 32, 92, 76
    segments: tuple[Segment, ...]
    end: Point


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class SingleCycle:
    """A G90 or G94 pass (:mod:`.single_cycles`), its moves planned in the program's coordinates; the tool ends at
    ``end`` (the start point)."""

    line: int
    code: int                       # 90, 94
    segments: tuple[Segment, ...]
    end: Point

    def removed(self) -> tuple[Point, ...]:
        """The region this pass cuts away by its definition: the quadrilateral its four moves enclose -- the start
        point, the cut's start (R's taper included), the cut's end, the corner straight out from it ((z, x), X a
        radius, the program's coordinates: work and tool offsets not applied)."""
        return tuple(g.element.start for g in self.segments)


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class PeckCycle:
    """A G74 (face peck drilling) or G75 (grooving) cycle (:mod:`.peck_cycles`), its moves planned in the program's
    coordinates; the tool ends at ``end`` (the start point). ``region``: what it cuts away by its definition."""

    line: int
    code: int                       # 74, 75
    segments: tuple[Segment, ...]
    end: Point
    region: tuple[Point, ...]

    def removed(self) -> tuple[Point, ...]:
        """The region this operation cuts away by its definition: a simple polygon of (Z, radius) points, mm, in the
        program's coordinates (work and tool offsets not applied, X as a radius), large values (1e4) standing for
        'to the outside'."""
        return self.region


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class PlannedCycle:
    """A cycle planned as the program is read (:mod:`.g72_g73`: G72, G73, and G70 finishing a G72 profile): its
    moves in the program's coordinates, the tool ending at ``end``; ``region`` what it cuts by its definition."""

    line: int
    code: int                           # 72, 73, or 70 (G70 along a G72 profile)
    segments: tuple[Segment, ...]
    end: Point
    start: Point                        # the cycle's start point (z, x)
    profile: Profile
    region: tuple[Point, ...]           # a simple polygon of (z, x radius) points: see :meth:`removed`
    shifts: tuple[Point, ...] = ()      # G73: each pass's shift of the profile (z, x radius), first to last

    def removed(self) -> tuple[Point, ...]:
        """The region this operation cuts away by its definition: a simple polygon of (Z, radius) points, mm, in
        the program's coordinates (work and tool offsets not applied, X as a radius), large values (1e4) standing
        for 'to the outside'."""
        return self.region


Op = Move | Rough | Finish | State | Dwell | Stop | Home | Thread | SingleCycle | PlannedCycle | PeckCycle


def _extreme(arc: Arc, angle: float) -> Point | None:
    """The arc's point in the direction ``angle`` from its centre, if it passes it strictly between its ends."""
    p = (arc.center[0] + arc.radius * math.cos(angle), arc.center[1] + arc.radius * math.sin(angle))
    return p if EPS < arc.param(p) < arc.length - EPS else None


def check_profile(profile: Profile, start: Point, inside: bool = False) -> int:
    """Toward -Z all along, inside the stock (below the start point's X, above the axis); returns the line where X
    first falls along -Z (a pocket or undercut: type II), 0 if it never does (type I).

    ``inside``: ``profile`` is an inside profile mirrored about the start point's X (:func:`mirror_profile`):
    inside the stock is then above the bore's start X (the messages say so, in the program's X), and the axis
    is no limit."""
    pocket = 0
    x0 = start[1]

    def real(x: float) -> float:
        return 2.0 * x0 - x if inside else x

    above = "below" if inside else "above"
    a = profile.lead.element.end
    if a[1] > start[1] + TOL:
        raise ProgramError(profile.lead.line, 1, profile.lead.raw,
                           f"the profile starts above the start point: X {a[1]:g} > {start[1]:g} (radius)")
    for pb in profile.blocks:
        e, line, raw = pb.element, pb.line, pb.raw
        s, t = e.start, e.end
        # an arc may pass an extreme of Z or X between its ends: by more than TOL, the profile is not monotone
        z_hi, z_lo, x_lo, x_hi = ((_extreme(e, a) for a in (0.0, math.pi, -math.pi / 2, math.pi / 2))
                                  if isinstance(e, Arc) else (None, None, None, None))
        if (z_hi and z_hi[0] > s[0] + TOL) or (z_lo and z_lo[0] < t[0] - TOL):
            raise ProgramError(line, 1, raw, "this arc turns back in Z: the profile must run toward the "
                                                        "chuck (-Z) all along")
        if t[0] > s[0] + TOL:
            raise ProgramError(line, 1, raw, f"the profile moves +Z here (Z {s[0]:g} -> {t[0]:g}): it must "
                                                        "run toward the chuck (-Z) all along")
        falls = t[1] < s[1] - TOL or bool(x_lo and x_lo[1] < s[1] - TOL) or bool(x_hi and x_hi[1] > t[1] + TOL)
        if falls and not pocket:
            pocket = line
        if isinstance(e, Line) and abs(t[0] - s[0]) <= TOL and t[1] < s[1] - TOL:
            # a wall falling at the profile's end (against the stock left standing there) or straight back up:
            # a groove of no width, which no pass can enter at most U deep
            k = profile.blocks.index(pb)
            after = profile.blocks[k + 1].element if k + 1 < len(profile.blocks) else None
            if after is None or (abs(after.start[0] - after.end[0]) <= TOL and after.end[1] > after.start[1]):
                raise ProgramError(line, 1, raw, "a groove of no width: this wall falls at the profile's end or "
                                                 "the next block climbs straight back up at the same Z")
        # an arc's highest and lowest points between its ends count as its ends do
        top = max(s[1], t[1], x_hi[1] if x_hi else -math.inf)
        if top > start[1] + TOL:
            raise ProgramError(line, 1, raw, f"the profile leaves the stock: X {real(top):.6g} {above} the start "
                                             f"point's X {start[1]:g}" + (" (an inside profile stays above the "
                                                                          "bore's start X)" if inside else ""))
        bottom = min(s[1], t[1], x_lo[1] if x_lo else math.inf)
        if bottom < -TOL and not inside:
            raise ProgramError(line, 1, raw, f"the profile crosses the spindle axis: X {bottom:.6g} < 0")
    if profile.blocks[-1].element.end[0] >= start[0] - TOL:
        last = profile.blocks[-1]
        raise ProgramError(last.line, 1, last.raw, "the profile ends in front of the start point's Z: nothing to cut")
    return pocket


#: Fanuc's imaginary tool-nose numbers mirrored in X (about a line of constant X).
_TIP_MIRRORED = {0: 0, 1: 4, 2: 3, 3: 2, 4: 1, 5: 5, 6: 8, 7: 7, 8: 6, 9: 9}


def mirrored(e: Element, x0: float) -> Element:
    """The element mirrored about X = ``x0`` (an arc's sense turns round)."""
    if isinstance(e, Line):
        return Line((e.start[0], 2.0 * x0 - e.start[1]), (e.end[0], 2.0 * x0 - e.end[1]))
    return Arc((e.center[0], 2.0 * x0 - e.center[1]), e.radius, -e.a0, -e.sweep)


def mirror_profile(profile: Profile, x0: float) -> Profile:
    """An inside profile mirrored about its start point's X = ``x0``: an outside profile below it, planned as one
    (the stock between the bore's start X and the profile, the roughing passes outward, the retract inward)."""
    def flip(m: Move) -> Move:
        return replace(m, element=mirrored(m.element, x0))

    return replace(profile, lead=flip(profile.lead), blocks=tuple(flip(m) for m in profile.blocks),
                   front=mirrored(profile.front, x0) if profile.front is not None else None, inside=False)


def mirror_op(op: Rough | Finish) -> Rough | Finish:
    """An inside G71/G70 as the outside one it mirrors (U's sign turns round: Fanuc's U < 0 of a bore)."""
    x0 = op.start[1]
    profile = mirror_profile(op.profile, x0)
    if isinstance(op, Rough):
        return replace(op, profile=profile, u=-op.u)
    nose = op.nose and Nose(-op.nose.side, op.nose.radius, _TIP_MIRRORED[op.nose.tip])
    return replace(op, profile=profile, nose=nose)


def _solve(e: Element, f, target: float) -> float:
    """Path length on ``e`` where the monotone coordinate ``f(point)`` reaches ``target`` (bisection)."""
    lo, hi = 0.0, e.length
    rising = f(e.end) > f(e.start)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if (f(e.point(mid)) < target) == rising:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def clip_front(chain: list[Element], z0: float) -> list[Element]:
    """The part of a chain running toward -Z that lies at Z <= ``z0``."""
    out: list[Element] = []
    for e in chain:
        if out:
            out.append(e)
        elif e.end[0] <= z0 - EPS:
            if e.start[0] <= z0:
                out.append(e)
            else:
                s = _solve(e, lambda p: p[0], z0)
                out.append(e.sub(s, e.length))
    return out


def monotone_pieces(chain: list[Element]) -> list[Element]:
    """The chain with every arc split where X turns (its lowest or highest point): each piece monotone in X."""
    out: list[Element] = []
    for e in chain:
        if isinstance(e, Arc):
            turns = sorted(e.param((e.center[0] + e.radius * math.cos(a), e.center[1] + e.radius * math.sin(a)))
                           for a in (math.pi / 2, -math.pi / 2))
            ends = [0.0, *(c for c in turns if EPS < c < e.length - EPS), e.length]
            out += [e.sub(a, b) for a, b in zip(ends, ends[1:])]
        else:
            out.append(e)
    return out


def below(pieces: list[Element], level: float, crossing: list[int] | None = None) -> list[tuple[float, float]]:
    """The Z ranges (high, low), front to back, where the chain (running toward -Z, each piece monotone) is below
    X ``level``; ranges of no length (a wall touching the level) are left out. ``crossing``: the indices, in
    order, of the pieces that cross the level (lowest X below it, highest at or above it) when the caller keeps
    them (:class:`_Levels`), so the cost grows with the crossings, not with the chain."""
    if crossing is None:
        crossing = [i for i, e in enumerate(pieces) if min(e.start[1], e.end[1]) < level <= max(e.start[1], e.end[1])]
    ranges: list[tuple[float, float]] = []

    def add(part: tuple[float, float]) -> None:
        if ranges and ranges[-1][1] - part[0] <= EPS:
            ranges[-1] = (ranges[-1][0], part[1])
        else:
            ranges.append(part)

    first = 0                                   # the run of pieces before the next crossing: all below or none
    for c in (*crossing, len(pieces)):
        if c > first and max(pieces[first].start[1], pieces[first].end[1]) < level:
            add((pieces[first].start[0], pieces[c - 1].end[0]))
        if c == len(pieces):
            break
        e = pieces[c]
        (zs, xs), (_, _) = e.start, e.end
        zc = e.point(_solve(e, lambda p: p[1], level))[0]
        add((zs, zc) if xs < level else (zc, e.end[0]))
        first = c + 1
    return [(hi, lo) for hi, lo in ranges if hi - lo > TOL]


class _Levels:
    """The pieces that cross a falling X level, kept level by level: a piece joins when the level falls to its
    highest X and leaves when the level falls to its lowest, so each level costs what crosses it."""

    def __init__(self, pieces: list[Element]) -> None:
        self.pieces = pieces
        self.low = [min(e.start[1], e.end[1]) for e in pieces]
        self.high = [max(e.start[1], e.end[1]) for e in pieces]
        self.waiting = sorted(range(len(pieces)), key=lambda i: -self.high[i])
        self.next = 0
        self.crossing: list[int] = []

    def ranges(self, level: float) -> list[tuple[float, float]]:
        """:func:`below` at ``level``, which is below every level asked before."""
        joined = False
        while self.next < len(self.waiting) and level <= self.high[self.waiting[self.next]]:
            self.crossing.append(self.waiting[self.next])
            self.next += 1
            joined = True
        self.crossing = [i for i in self.crossing if self.low[i] < level]
        if joined:
            self.crossing.sort()
        return below(self.pieces, level, self.crossing)


def rough_boundary(op: Rough) -> list[Element]:
    """The profile shifted by the allowances (W in Z, U in X), from the start point's Z on."""
    return clip_front([shifted(e, op.w, op.u) for e in op.profile.outline], op.start[0])


class _Stock:
    """What is left of the stock: up to X ``top`` (the start point's) behind Z ``front``, cut down by the passes.

    The Z coordinates where a cut may begin or end are known before the first cut (``coords``, the ranges of
    every level); the stock is kept on them -- each coordinate a slot, each open interval between two a slot --
    in a segment tree of the highest X of material, so a cut and a question cost log(coordinates). A cut lowers
    its slots to its X (levels fall: never raises one); a cut or a question counts a point within ``EPS`` of a
    coordinate as on it."""

    def __init__(self, top: float, front: float, coords: list[float]) -> None:
        self.top, self.front = top, front
        self.coords = sorted({*coords, front})
        m = len(self.coords)
        self.slots = 2 * m + 1          # interval 0, point 0, interval 1, ..., point m-1, interval m
        size = 1
        while size < self.slots:
            size *= 2
        self.size = size
        self.high = [-math.inf] * (2 * size)
        self.lazy: list[float | None] = [None] * (2 * size)
        k = self.coords.index(front)
        for slot in range(2 * k + 1):     # behind the front: the stock's top; from the front on: air
            self.high[size + slot] = top
        for i in range(size - 1, 0, -1):
            self.high[i] = max(self.high[2 * i], self.high[2 * i + 1])

    def _assign(self, node: int, x: float) -> None:
        if x < self.high[node]:
            self.high[node] = x
        self.lazy[node] = x if self.lazy[node] is None else min(x, self.lazy[node])  # type: ignore[type-var]

    def _lower(self, node: int, lo: int, hi: int, a: int, b: int, x: float) -> None:
        if b < lo or hi < a:
            return
        if a <= lo and hi <= b:
            self._assign(node, x)
            return
        self._push(node)
        mid = (lo + hi) // 2
        self._lower(2 * node, lo, mid, a, b, x)
        self._lower(2 * node + 1, mid + 1, hi, a, b, x)
        self.high[node] = max(self.high[2 * node], self.high[2 * node + 1])

    def _push(self, node: int) -> None:
        if self.lazy[node] is not None:
            self._assign(2 * node, self.lazy[node])        # type: ignore[arg-type]
            self._assign(2 * node + 1, self.lazy[node])    # type: ignore[arg-type]
            self.lazy[node] = None

    def _max(self, node: int, lo: int, hi: int, a: int, b: int) -> float:
        if b < lo or hi < a:
            return -math.inf
        if a <= lo and hi <= b:
            return self.high[node]
        self._push(node)
        mid = (lo + hi) // 2
        return max(self._max(2 * node, lo, mid, a, b), self._max(2 * node + 1, mid + 1, hi, a, b))

    def _span(self, a: int, b: int) -> float:
        return self._max(1, 0, self.size - 1, a, b) if a <= b else -math.inf

    def cut(self, z_lo: float, z_hi: float, x: float) -> None:
        first = bisect_left(self.coords, z_lo - EPS)
        last = bisect_right(self.coords, z_hi + EPS) - 1
        if first <= last:
            self._lower(1, 0, self.size - 1, 2 * first + 1, 2 * last + 1, x)

    def at(self, z: float) -> float:
        """The highest X of material at ``z`` (-inf in front of the stock)."""
        if z >= self.front - EPS:
            return -math.inf
        first = bisect_left(self.coords, z - EPS)
        last = bisect_right(self.coords, z + EPS) - 1
        k = bisect_left(self.coords, z)
        on = k < len(self.coords) and self.coords[k] == z
        near = self._span(2 * first + 1, 2 * last + 1) if first <= last else math.inf
        inside = math.inf if on else self._span(2 * k, 2 * k)
        return min(near, inside)

    def highest(self, z_a: float, z_b: float) -> float:
        """The highest X of material anywhere in Z between ``z_a`` and ``z_b``."""
        lo, hi = min(z_a, z_b), max(z_a, z_b)
        ends = max(self.at(lo), self.at(hi))
        if lo == hi:
            return ends
        # the slots strictly between: from the interval after lo to the interval before hi
        a = bisect_right(self.coords, lo)
        b = bisect_left(self.coords, hi)
        return max(ends, self._span(2 * a, 2 * b))


def _plan_rough(op: Rough, rapid: float) -> list[Segment]:
    """The passes: at X = S.x - k*U, one pass per Z range where the rough boundary lies below that X (one range
    for a monotone profile; each pocket adds its own), each the seed's SC1-SC4; then the pass along the boundary.
    SC1 reaches a pass's start clear of the material left: up, along Z, down (into a pocket at the feed)."""
    z0, x0 = op.start
    bound = rough_boundary(op)
    pieces = monotone_pieces(bound)
    x_min = min(min(e.start[1], e.end[1]) for e in pieces)
    if (x0 - x_min) / op.depth > MAX_SEGMENTS / 4:
        raise ProgramError(op.line, 1, f"line {op.line}", f"more than {MAX_SEGMENTS // 4} passes of U{op.depth:g} "
                                                          f"down to X {x_min:g}: U is too small")
    x_max = max(max(e.start[1], e.end[1]) for e in pieces)
    # the passes are counted before one is planned: each at least SC1, SC2, SC3, SC4
    levels: list[tuple[float, list[tuple[float, float]]]] = []
    crossings = _Levels(pieces)
    passes, n = 0, 0
    level = x0 - op.depth
    while level > x_min + TOL:
        ranges = crossings.ranges(level)
        levels.append((level, ranges))
        passes += len(ranges)
        if 4 * passes + len(bound) > MAX_SEGMENTS:
            raise ProgramError(op.line, 1, f"line {op.line}", f"more than {MAX_SEGMENTS} moves: {passes} passes "
                                                              f"of U{op.depth:g} down to X {level:g} already: U is "
                                                              "too small")
        n += 1
        level = x0 - (n + 1) * op.depth
    stock = _Stock(x0, z0, [z for _, ranges in levels for r in ranges for z in r])
    out: list[Segment] = []
    here = op.start
    k = 0

    def add(to: Point, rate: float, feed: bool, sub: int, sigma: float) -> None:
        nonlocal here
        out.append(Segment(Line(here, to), rate, feed, sub, k, sigma, op.line, 71))
        here = to
        if len(out) > MAX_SEGMENTS:
            raise ProgramError(op.line, 1, f"line {op.line}", f"more than {MAX_SEGMENTS} moves: U is too small")

    def reach(z: float, x: float, plunge: bool, sigma: float) -> None:
        """SC1: from where the tool is to (z, x) over the material between, the last leg down."""
        clear = max(stock.highest(here[0], z) + op.retract, here[1], x)
        if clear > here[1] + EPS:
            add((here[0], clear), rapid, False, 1, sigma)
        if abs(z - here[0]) > EPS:
            add((z, clear), rapid, False, 1, sigma)
        add((z, x), op.feed if plunge else rapid, plunge, 1, sigma)

    for level, ranges in levels:
        sigma = x0 - level
        for z_hi, z_lo in ranges:
            k += 1
            reach(z_hi, level, z_hi < z0 - TOL, sigma)           # in front of the stock at rapid, else a plunge
            add((z_lo, level), op.feed, True, 2, sigma)
            stock.cut(z_lo, z_hi, level)
            add((z_lo, level + op.retract), rapid, False, 3, sigma)
            add((z_hi, level + op.retract), rapid, False, 4, sigma)
    k += 1
    sigma = x0 - x_min
    reach(bound[0].start[0], bound[0].start[1], True, sigma)
    for e, line in zip(bound, _lines_of(op, bound)):
        out.append(Segment(e, op.feed, True, 2, k, sigma, line, 71))
    end = bound[-1].end
    here = end
    add((end[0], x_max + op.retract), rapid, False, 3, sigma)
    add((z0, x_max + op.retract), rapid, False, 4, sigma)
    k = 0
    add(op.start, rapid, False, 0, 0.0)
    return out


def _lines_of(op: Rough, bound: list[Element]) -> list[int]:
    """The program line of each element of the rough boundary (the clipped chain keeps the tail's order)."""
    lines = ([op.profile.lead.line] if op.profile.front is not None else []) + [pb.line for pb in op.profile.blocks]
    return lines[len(lines) - len(bound):]


def finish_chain(op: Finish) -> list[Element]:
    """What G70 runs along under G41/G42: the profile, then up the wall it ends at (SC3) to the start point's X
    (the wall is part's too: the nose must not gouge it)."""
    chain = [pb.element for pb in op.profile.blocks]
    bz, bx = chain[-1].end
    if op.start[1] > bx + EPS:
        chain.append(Line((bz, bx), (bz, op.start[1])))
    return chain


def finish_path(op: Finish) -> list[tuple[Element, int]]:
    """The commanded pieces of G70 under G41/G42 (:meth:`.nose.Nose.path` of :func:`finish_chain`): (piece, index
    of its profile block; ``len(profile.blocks)``: the wall up at the end).

    Raises
    ------
    ProgramError
        naming the profile's block where the nose cannot follow the profile.
    """
    assert op.nose is not None
    if op.profile.inside:
        return [(mirrored(e, op.start[1]), k) for e, k in finish_path(mirror_op(op))]   # type: ignore[arg-type]
    blocks = op.profile.blocks
    try:
        return op.nose.path(finish_chain(op))
    except CornerError as err:
        names = [f"the block on line {pb.line}" for pb in blocks] + [f"G70's retract up the end wall (line {op.line})"]
        at = blocks[err.index] if err.index < len(blocks) else None
        raise ProgramError(at.line if at else op.line, 1, at.raw if at else f"line {op.line}",
                           f"tool-nose radius compensation ({op.nose.code}, nose radius {op.nose.radius:g} mm): "
                           f"{err.describe(names)}") from None


def _plan_finish_nose(op: Finish, rapid: float) -> list[Segment]:
    """G70 under G41/G42: SC1 from the start point to the nose's first point (type A start-up), SC2 the
    compensated profile, SC3 the compensated wall up, SC4 back to the start point's Z at its X (the cancel)."""
    out: list[Segment] = []
    z0, x0 = op.start
    lead, blocks = op.profile.lead, op.profile.blocks
    up = op.feed or blocks[-1].feed
    assert op.nose is not None

    def rate(pb: Move) -> tuple[float, bool]:
        return (rapid, False) if pb.rapid else (op.feed or pb.feed, True)

    pieces = finish_path(op)
    r, f = rate(lead)
    out.append(Segment(Line(op.start, pieces[0][0].start), r, f, 1, 1, 0.0, lead.line, 70))
    for e, k in pieces:
        if k < len(blocks):
            r, f = rate(blocks[k])
            out.append(Segment(e, r, f, 2, 1, 0.0, blocks[k].line, 70))
        else:
            out.append(Segment(e, up or rapid, up > 0, 3, 1, 0.0, op.line, 70))
    # SC4: straight up until the nose circle is clear of the stock's X (its centre r above it), along Z to the
    # start point's Z, down to the start point
    last = pieces[-1][0].end
    high = max(last[1], x0 + op.nose.radius + op.nose.vector[1])
    for a, b, sub in ((last, (last[0], high), 4), ((last[0], high), (z0, high), 4), ((z0, high), op.start, 0)):
        out.append(Segment(Line(a, b), rapid, False, sub, 1 if sub else 0, 0.0, op.line, 70))
    return [g for g in out if g.element.length > EPS]


def _plan_finish(op: Finish, rapid: float) -> list[Segment]:
    if op.nose is not None:
        return _plan_finish_nose(op, rapid)
    out: list[Segment] = []
    z0, x0 = op.start
    a = op.profile.lead.element.end
    lead = op.profile.lead

    def rate(pb: Move) -> tuple[float, bool]:
        return (rapid, False) if pb.rapid else (op.feed or pb.feed, True)

    r, f = rate(lead)
    out.append(Segment(Line(op.start, a), r, f, 1, 1, 0.0, lead.line, 70))
    for pb in op.profile.blocks:
        r, f = rate(pb)
        out.append(Segment(pb.element, r, f, 2, 1, 0.0, pb.line, 70))
    bz, bx = op.profile.blocks[-1].element.end
    # SC4 returns along Z above every point of the profile: a G73 pass (a profile shifted up by the escape) may
    # rise above the start point's X where the blank is still standing (a G70/G71 profile never does)
    clear = max([x0] + [bounds(pb.element)[3] for pb in op.profile.blocks])
    # up the wall the profile ends at, at the feed: below the stock's X the roughing left its allowance there
    up = op.feed or op.profile.blocks[-1].feed
    out.append(Segment(Line((bz, bx), (bz, clear)), up or rapid, up > 0, 3, 1, 0.0, op.line, 70))
    out.append(Segment(Line((bz, clear), (z0, clear)), rapid, False, 4, 1, 0.0, op.line, 70))
    if clear > x0:
        out.append(Segment(Line((z0, clear), op.start), rapid, False, 0, 0, 0.0, op.line, 70))
    return out


def plan_cycle(op: Rough | Finish, rapid: float) -> list[Segment]:
    """The moves of a G71 or G70; an inside one planned as the outside one it mirrors, and mirrored back."""
    if op.profile.inside:
        x0 = op.start[1]
        return [replace(g, element=mirrored(g.element, x0)) for g in plan_cycle(mirror_op(op), rapid)]
    return _plan_rough(op, rapid) if isinstance(op, Rough) else _plan_finish(op, rapid)


def plan_ops(ops: list[Op], rapid: float, start: Point | None = None) -> list[Segment]:
    """The planned moves of a program's operations, the tool at ``start`` ((z, x), programmed = axes: no tool
    offset yet; the first operation's start when None). Each move in the axes' coordinates (the programmed
    point + the active tool offset) and with the state it runs in; a new tool offset is taken up by a rapid move
    where the T word stands, dwells and stops are moves of no length."""
    out: list[Segment] = []
    modal = NO_MODAL
    here = start if start is not None else _start_of(ops)          # programmed point
    dz = dx = 0.0

    def axes(p: Point) -> Point:
        return (p[0] + dz, p[1] + dx)

    def still(line: int, **kw: object) -> Segment:
        p = axes(here)
        return Segment(Line(p, p), rapid, False, 0, 0, 0.0, line, 0, modal=modal, **kw)  # type: ignore[arg-type]

    for op in ops:
        if isinstance(op, Move):
            e = op.element if (dz, dx) == (0.0, 0.0) else shifted(op.element, dz, dx)
            out.append(Segment(e, rapid if op.rapid else op.feed, not op.rapid, 0, 0, 0.0, op.line, 0, modal=modal))
            here = op.element.end
        elif isinstance(op, (Rough, Finish)):
            segs = plan_cycle(op, rapid)
            if (dz, dx) != (0.0, 0.0) or modal != NO_MODAL:
                segs = [replace(g, element=shifted(g.element, dz, dx), modal=modal) for g in segs]
            out += segs
            here = op.start
        elif isinstance(op, (Thread, SingleCycle, PlannedCycle, PeckCycle)):
            out += [replace(g, element=shifted(g.element, dz, dx), modal=modal, rate=g.rate if g.feed else rapid)
                    for g in op.segments]
            here = op.end
        elif isinstance(op, State):
            before = axes(here)
            modal = op.modal
            dz, dx = modal.offset
            if op.power_on and start is not None:   # a power-on work offset (G54): the axes stand at start
                here = (before[0] - dz, before[1] - dx)
            if math.dist(before, axes(here)) > EPS:             # the new offset taken up at the rapid rate
                out.append(Segment(Line(before, axes(here)), rapid, False, 0, 0, 0.0, op.line, 0, modal=modal))
        elif isinstance(op, Dwell):
            out.append(still(op.line, dwell=op.seconds))
        elif isinstance(op, Stop):
            out.append(still(op.line, stop=2 if op.optional else 1))
        else:
            p = axes(here)
            via = axes(op.via)
            home = (op.home[0] if op.home[0] is not None else via[0], op.home[1] if op.home[1] is not None else via[1])
            for a, b in ((p, via), (via, home)):
                if math.dist(a, b) > EPS:
                    out.append(Segment(Line(a, b), rapid, False, 0, 0, 0.0, op.line, 0, modal=modal))
            here = (home[0] - dz, home[1] - dx)
    if out and out[-1].modal != modal:                 # the state the program ends in (M05, M09 at its end)
        out.append(still(out[-1].line))
    for g in out:
        m = g.modal
        if g.feed and m.per_rev and not (m.spindle and m.s > 0):
            raise ProgramError(g.line, 1, f"line {g.line}", "a feed per revolution (G99) with the spindle stopped: "
                                                            "give S and M03/M04 first")
    return out


def _start_of(ops: list[Op]) -> Point:
    for op in ops:
        if isinstance(op, Move):
            return op.element.start
        if isinstance(op, (Rough, Finish)):
            return op.start
    return (0.0, 0.0)
