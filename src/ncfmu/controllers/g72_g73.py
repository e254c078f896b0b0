"""The lathe's G72 (stock removal in facing) and G73 (pattern repeat), and G70 finishing a G72 profile -- Fanuc
0i-T's cycles, planned as the program is read into :class:`.g7x.Segment` s (the seed's sub-cycles SC1-SC4).

Geometry in the (z, x) plane, X a radius (as :mod:`.lathe_program`); S the start point (where the tool stands).

G72 is G71 with the roles of the axes swapped: its profile N<P>..N<Q> starts with a move in Z only, from S toward
the chuck to the profile's start A (at S's X); the rest runs toward the spindle axis (X never rises) and toward S's
Z (Z never falls: Fanuc's type I, monotonic; a pocket is refused). The stock is what lies between the profile and
S's Z, below S's X. The passes run parallel to X (SC2 from S's X toward the axis), each the depth W(Δd) deeper in Z,
SC3 retracts by R(e) at 45 degrees (+Z and +X, as Fanuc draws it), SC4 returns in +X; then one pass along the
profile shifted by the allowances U (in X, the X mode's) and W, so the finishing pass G70 takes the allowance
everywhere. Seen with Z and X exchanged (:func:`exchanged`: a reflection about the line Z = X) a G72 profile *is* a
G71 profile of type I -- its lead in (exchanged) X only, running toward (exchanged) -Z, monotone -- so G72 is
planned as that G71 (:func:`.g7x.plan_cycle`) and exchanged back, and G70 of a G72 profile likewise: SC3 leaves the
face in +Z to S's Z, SC4 returns in +X.

G73 repeats the whole profile (its first block a straight move from S to the profile's start, the rest
running toward the chuck, X free: pockets are fine, as on a cast or forged blank -- then without a shift in Z,
which would move a pocket's near wall into the part) R(d) times, pass k
(1..d) shifted by the finishing allowance (U/2 [radius], W) plus (Δi, Δk) (d - k) / (d - 1): the first pass
(Δi + U/2, Δk + W) off the profile, the last on the allowance, the steps between even. Each pass is G70's path
along the shifted profile (SC1 from S to the shifted start, SC2 the profile at G73's feed, the profile's G00
blocks at the rapid rate, SC3 up the end wall to S's X, SC4 back to S's Z).

Each cycle is a :class:`.g7x.PlannedCycle`, the region it cuts by its definition its ``removed()`` (the part
check's programmed part: the stock less them), a simple polygon of (Z, radius) points, :data:`FAR` standing for
"to the outside".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ..errors import ProgramError
from .g7x import ARC_SPACING, EPS, FAR, MAX_SEGMENTS, TOL, Finish, PlannedCycle, Profile, Rough, Segment, plan_cycle
from .gcode import Block, Move
from .geometry import Arc, Element, Line, Point, bounds, sample
from .mypyc_compat import mypyc_attr
from .nose import translated


# -- the exchange of Z and X ------------------------------------------------------------------------------
def exchanged(e: Element) -> Element:
    """The element reflected about the line Z = X: (z, x) -> (x, z) (an arc's sense turns round)."""
    if isinstance(e, Line):
        return Line((e.start[1], e.start[0]), (e.end[1], e.end[0]))
    return Arc((e.center[1], e.center[0]), e.radius, math.pi / 2 - e.a0, -e.sweep)


def _exchanged_move(m: Move) -> Move:
    return replace(m, element=exchanged(m.element))


def _exchanged_profile(profile: Profile) -> Profile:
    return replace(profile, lead=_exchanged_move(profile.lead),
                   blocks=tuple(_exchanged_move(m) for m in profile.blocks), front=None)


def _exchanged_back(segments: list[Segment], code: int) -> tuple[Segment, ...]:
    return tuple(replace(g, element=exchanged(g.element), cycle=code) for g in segments)


#: The rapid rate the cycles are planned with as they are read: :func:`.g7x.plan_ops` gives every rapid move
#: the sequencer's rate.
_PLANNING_RAPID = 1.0


# -- the operations ---------------------------------------------------------------------------------------
def _above(profile: Profile) -> tuple[Point, ...]:
    """What G73 (and its G70) cuts away: everything above the profile between its ends' Z (an outside profile
    running toward the chuck)."""
    points = sample([m.element for m in profile.blocks], ARC_SPACING)
    (za, _), (zb, _) = points[0], points[-1]
    return (*points, (zb, FAR), (za, FAR))


def _in_front(profile: Profile) -> tuple[Point, ...]:
    """What G72 (and its G70) cuts away: everything in front of (+Z of) the profile between its ends' X."""
    points = sample([m.element for m in profile.blocks], ARC_SPACING)
    (_, xa), (_, xb) = points[0], points[-1]
    return (*points, (FAR, xb), (FAR, xa))


# -- the blocks -------------------------------------------------------------------------------------------
@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class FirstBlock:
    """A G72's or G73's first block: G72 W(depth) R(retract) -- ``a`` the depth, ``r`` the retract; G73 U(Δi)
    W(Δk) R(d) -- ``a`` Δi (radius), ``b`` Δk, ``r`` the number of passes."""

    code: int
    a: float
    b: float
    r: float


def first_block(b: Block) -> FirstBlock:
    """G72 W R / G73 U W R (the block without P and Q), its words checked."""
    v = b.values
    code = 72 if any(g == 72 for g, _ in b.g) else 73
    words = "WR" if code == 72 else "UWR"
    meaning = ("the depth of cut W and the retract R" if code == 72 else
               "the escape U (X, radius), the escape W (Z) and the number of passes R")
    missing = [k for k in words if k not in v]
    if missing:
        raise b.err(1, f"G{code}'s first block gives {meaning}: {', '.join(missing)} missing")
    for k in "UF" if code == 72 else "F":
        if k in v:
            raise b.err(b.col(k), f"{k}: belongs to G{code}'s second block (G{code} P Q U W F)")
    if code == 72:
        if not v["W"] > 0:
            raise b.err(b.col("W"), f"W{v['W']:g}: the depth of cut must be > 0")
        if v["R"] < 0:
            raise b.err(b.col("R"), f"R{v['R']:g}: the retract must be >= 0")
        return FirstBlock(72, v["W"], 0.0, v["R"])
    d = v["R"]
    if d != int(d) or d < 1:
        raise b.err(b.col("R"), f"R{d:g}: G73's R is the number of passes, a whole number >= 1")
    for k in "UW":
        if v[k] < 0:
            raise b.err(b.col(k), f"{k}{v[k]:g}: the escape must be >= 0 (a negative one shifts the first pass into "
                                  "the part)")
    if d == 1 and (v["U"] or v["W"]):
        raise b.err(b.col("R"), f"R1 with U{v['U']:g} W{v['W']:g}: one pass cannot be both the first (off the profile "
                                "by the escape) and the last (on the finishing allowance): give R >= 2, or U0 W0")
    if d * 4 > MAX_SEGMENTS:
        raise b.err(b.col("R"), f"R{d:g}: more than {MAX_SEGMENTS // 4} passes")
    return FirstBlock(73, v["U"], v["W"], d)


def first_block_error(code: int, element: Element | None, start: Point, end: Point) -> str:
    """Why the profile's first block (``element`` from ``start`` to ``end``) is not G72's or G73's form ("" when it
    is)."""
    if code == 72:
        if (element is None or not isinstance(element, Line) or abs(end[1] - start[1]) > TOL
                or end[0] > start[0] - EPS):
            return (f"G72's profile starts with a move in Z only (G00/G01 Z or W), from the start point (X "
                    f"{start[1]:g}, Z {start[0]:g}) toward the chuck (Fanuc's form)")
        return ""
    if element is None or not isinstance(element, Line):
        return (f"G73's profile starts with a straight move (G00/G01) from the start point (X {start[1]:g}, Z "
                f"{start[0]:g}) to the profile's start")
    if end[1] > start[1] + TOL:
        return (f"the profile starts above the start point: X {end[1]:g} > {start[1]:g} (radius): G73's start point "
                "stands outside the blank (a bore by G73 is not in the subset)")
    return ""


def check_profile(code: int, profile: Profile, start: Point) -> None:
    """A G72 profile: toward the axis (X never rises) and toward the start point's Z (Z never falls), at most S's
    Z, above the axis. A G73 profile: toward the chuck (Z never rises), at most S's X, above the axis. Raises
    ProgramError naming the block that is not."""
    z0, x0 = start
    for pb in profile.blocks:
        e = pb.element
        (s, t) = e.start, e.end
        z_lo, x_lo, z_hi, x_hi = bounds(e)
        if code == 72:
            if t[0] < s[0] - TOL or z_lo < s[0] - TOL or z_hi > t[0] + TOL:
                raise ProgramError(pb.line, 1, pb.raw, f"the profile moves -Z here (Z {s[0]:g} -> {z_lo:.6g}): a G72 "
                                                       "profile is monotonic, Z never falls from the first block's "
                                                       "end toward the start point's Z (a pocket is not G72's type I)")
            if t[1] > s[1] + TOL or x_hi > s[1] + TOL or x_lo < t[1] - TOL:
                raise ProgramError(pb.line, 1, pb.raw, f"the profile moves +X here (X {s[1]:g} -> {x_hi:.6g}, radius): "
                                                       "a G72 profile is monotonic, X never rises on the way toward "
                                                       "the axis")
            if z_hi > z0 + TOL:
                raise ProgramError(pb.line, 1, pb.raw, f"the profile leaves the stock: Z {z_hi:g} in front of the "
                                                       f"start point's Z {z0:g}")
        elif t[0] > s[0] + TOL or z_hi > s[0] + TOL:
            raise ProgramError(pb.line, 1, pb.raw, f"the profile moves +Z here (Z {s[0]:g} -> {z_hi:.6g}): a G73 "
                                                   "profile runs toward the chuck (-Z) all along (X may fall and "
                                                   "rise)")
        elif x_hi > x0 + TOL:
            raise ProgramError(pb.line, 1, pb.raw, f"the profile rises above the start point's X {x0:g} here (X "
                                                   f"{x_hi:.6g}, radius): each pass returns to the start point's Z "
                                                   "at its X, through the part there; start G73 above the part")
        if x_lo < -TOL:
            raise ProgramError(pb.line, 1, pb.raw, f"the profile crosses the spindle axis: X {x_lo:.6g} < 0")
    last = profile.blocks[-1]
    if code == 72 and last.element.end[1] >= x0 - TOL:
        raise ProgramError(last.line, 1, last.raw, f"the profile never leaves the start point's X {x0:g}: nothing to "
                                                   "face")
    if code == 73 and last.element.end[0] >= z0 - TOL:
        raise ProgramError(last.line, 1, last.raw, "the profile ends in front of the start point's Z: nothing to cut")


def face_rough(b: Block, first: FirstBlock, start: Point, profile: Profile, u: float, w: float,
               feed: float) -> PlannedCycle:
    """G72 P Q U W F (``b``) after ``first`` from ``start``: ``u`` the X allowance (radius), ``w`` the Z one."""
    z0, x0 = start
    for k, value in (("U", u), ("W", w)):
        if value < 0:
            raise b.err(b.col(k), f"{k}{b.values[k]:g}: a negative allowance would cut into the part (G72 faces "
                                  "toward the chuck and the axis)")
    if profile.blocks[-1].element.end[1] + u >= x0 - TOL:
        raise b.err(b.col("U"), f"U{b.values.get('U', 0.0):g}: the profile shifted by the X allowance ends at the "
                                f"start point's X {x0:g} or outside it: nothing to face")
    deepest = profile.lead.element.end[0] + w
    if deepest >= z0 - TOL:
        raise b.err(b.col("W"), f"W{w:g}: the profile shifted by the Z allowance lies nowhere behind the start "
                                f"point's Z {z0:g}: nothing to face")
    if (z0 - deepest) / first.a > MAX_SEGMENTS / 4:
        raise b.err(1, f"more than {MAX_SEGMENTS // 4} passes of W{first.a:g} down to Z {deepest:g}: the depth of cut "
                       "is too small")
    rough = Rough(b.line, (x0, z0), _exchanged_profile(profile), first.a, first.r, w, u, feed)
    segments = _retracts_at_45_degrees(_exchanged_back(plan_cycle(rough, _PLANNING_RAPID), 72), first.r, x0)
    return PlannedCycle(b.line, 72, segments, start, start, profile, _in_front(profile))


def _retracts_at_45_degrees(segments: tuple[Segment, ...], retract: float, x0: float) -> tuple[Segment, ...]:
    """Each level's SC3 as Fanuc draws G72's: by the retract in +Z *and* +X (at most up to the start point's X),
    SC4 from there. Straight off in +Z the insert's end edge would drag across the wedge its clearance angle left
    on the face below it; at 45 degrees it leaves the face (the pass's floor stays behind it). The pass along the
    profile too: it ends on the profile's last face, inside the stock when that face is."""
    out = list(segments)
    for k, g in enumerate(out):
        if g.subcycle == 3 and g.pass_no > 0 and k + 1 < len(out) and out[k + 1].subcycle == 4:
            (z, x), (z1, _) = g.element.start, g.element.end
            corner = (z1, x + min(retract, x0 - x))
            out[k] = replace(g, element=Line((z, x), corner))
            out[k + 1] = replace(out[k + 1], element=Line(corner, out[k + 1].element.end))
    return tuple(g for g in out if g.element.length > EPS)


def face_finish(b: Block, start: Point, profile: Profile, feed: float, comp: int) -> PlannedCycle:
    """G70 P Q F (``b``) along a G72 profile from ``start``; ``comp`` the tool-nose compensation in force."""
    if comp:
        raise b.err(b.col("G"), f"G70 of a G72 profile with G4{1 if comp > 0 else 2} in force: the tool-nose radius "
                                "compensation of a face profile is not in the subset (cancel it with G40 first)")
    z0, x0 = start
    finish = Finish(b.line, (x0, z0), _exchanged_profile(profile), feed)
    segments = tuple(g for g in _exchanged_back(plan_cycle(finish, _PLANNING_RAPID), 70) if g.element.length > EPS)
    return PlannedCycle(b.line, 70, segments, start, start, profile, _in_front(profile))


def _falls(e: Element) -> bool:
    """X falls somewhere along the element (toward -Z): a pocket's near wall or an undercut."""
    _, x_lo, _, _ = bounds(e)
    return e.end[1] < e.start[1] - TOL or x_lo < min(e.start[1], e.end[1]) - TOL


def pattern_shifts(first: FirstBlock, u: float, w: float) -> tuple[Point, ...]:
    """The shift (z, x radius) of each pass of G73: the first by the escape plus the allowance, the last by the
    allowance, the steps between even."""
    d = int(first.r)
    if d == 1:
        return ((w, u),)
    return tuple((w + first.b * (d - k) / (d - 1), u + first.a * (d - k) / (d - 1)) for k in range(1, d + 1))


def pattern_repeat(b: Block, first: FirstBlock, start: Point, profile: Profile, u: float, w: float,
                   feed: float) -> PlannedCycle:
    """G73 P Q U W F (``b``) after ``first`` from ``start``: ``u`` the X allowance (radius), ``w`` the Z one."""
    for k, value in (("U", u), ("W", w)):
        if value < 0:
            raise b.err(b.col(k), f"{k}{b.values[k]:g}: a negative allowance would cut into the part (an outside "
                                  "profile turned toward the chuck)")
    falls = next((pb for pb in profile.blocks if _falls(pb.element)), None)
    if falls is not None and (w > 0 or first.b > 0):
        k = "W" if w > 0 else "G"
        raise b.err(b.col(k), f"W{w:g} (Z allowance) with an escape W{first.b:g} (Z): the profile has a pocket (X "
                              f"falls along -Z on line {falls.line}): a shift in Z moves its near wall into the part; "
                              "give W0 in both G73 blocks (the pattern then steps in X alone)")
    shifts = pattern_shifts(first, u, w)
    if len(shifts) * (len(profile.blocks) + 5) > MAX_SEGMENTS:
        raise b.err(1, f"more than {MAX_SEGMENTS} planned moves: {len(shifts)} passes of {len(profile.blocks)} blocks")
    segments: list[Segment] = []
    (za, xa) = profile.lead.element.end
    for n, (dz, dx) in enumerate(shifts, 1):
        lead = replace(profile.lead, element=Line(start, (za + dz, xa + dx)))
        shifted = replace(profile, lead=lead,
                          blocks=tuple(replace(m, element=translated(m.element, dz, dx)) for m in profile.blocks))
        segments += [replace(g, cycle=73, pass_no=n if g.subcycle else 0)
                     for g in plan_cycle(Finish(b.line, start, shifted, feed), _PLANNING_RAPID)
                     if g.element.length > EPS]
    return PlannedCycle(b.line, 73, tuple(segments), start, start, profile, _above(profile), shifts)
