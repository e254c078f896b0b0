"""Lathe part programs: an RS274 lathe subset with G71 stock removal and G70 finishing, planned as the
seed's sub-cycles (US 4,017,723: SC1 infeed, SC2 cut, SC3 retract, SC4 return).

Words (one block per line, letters in either case)::

    G00 rapid   G01 line   G02 clockwise arc   G03 counter-clockwise arc        (motion, modal)
    G18 XZ plane   G21 mm   G90 absolute   G91 incremental                       (modal)
    G7 X is a diameter   G8 X is a radius (the default, as everywhere in ncfmu)  (modal)
    X Z end point   I K arc centre relative to the arc's start (radius values)   R arc radius
    F feed in mm/min (modal)   N block number   M02 / M30 program end
    G71 U<depth of cut> R<retract>                first block: radius values
    G71 P<first N> Q<last N> U<X allowance> W<Z allowance> [F]  second block: U in the X mode in force
    G70 P<first N> Q<last N> [F]                  one pass along the profile
    ( comment )   ; comment to the end of the line   a line holding only % is skipped

Geometry: elements (:class:`.geometry.Line`, :class:`.geometry.Arc`) in the **(z, x) plane** -- first
coordinate Z (to the right), second X (the radius, up), as a lathe drawing shows the part. Seen from +Y,
RS274/NGC's G02 is clockwise with Z to the right and X up, so G02 is a clockwise arc of the geometry (negative
sweep) and G03 a counter-clockwise one. The controller's commands are (x, z): :func:`xz` turns a point round.

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
from .geometry import Arc, Element, Line, Point, arc_through
from .motion import LinearMove
from .rs274 import ARC_RADIUS_TOLERANCE, COORDINATE_LIMIT, check_once, program_lines, strip_comments, words

#: More planned moves than this are refused: one part, a few hundred passes at most.
MAX_SEGMENTS = 20_000
#: Points closer than this are one point (mm).
EPS = 1e-9
#: Geometric tolerance of the profile checks (monotone, inside the stock), mm.
TOL = 1e-6
#: On an arc: tangential and centripetal acceleration as fractions of ``accel`` (as the contour interpolator).
ARC_TANGENTIAL, ARC_CENTRIPETAL = 0.8, 0.55

_MOTION = {0, 1, 2, 3}
_GROUPS = {**{g: "motion (G00-G03)" for g in _MOTION}, 18: "plane (G18)", 21: "units (G21)",
           90: "distance mode (G90/G91)", 91: "distance mode (G90/G91)", 7: "X mode (G7/G8)", 8: "X mode (G7/G8)",
           70: "canned cycle (G70/G71)", 71: "canned cycle (G70/G71)"}
_REFUSED_G = {17: "a lathe works in the XZ plane (G18)", 19: "a lathe works in the XZ plane (G18)",
              20: "inch units are not in the subset: write the program in mm (G21)",
              40: "tool nose radius compensation is not in the subset (the tool point is programmed)",
              41: "tool nose radius compensation is not in the subset (the tool point is programmed)",
              42: "tool nose radius compensation is not in the subset (the tool point is programmed)",
              72: "G72 (facing stock removal) is not in the subset: G71 and G70 are",
              73: "G73 (pattern repeat) is not in the subset: G71 and G70 are"}


def xz(p: Point) -> tuple[float, float]:
    """A (z, x) point of the geometry as the controller's (x, z)."""
    return (p[1], p[0])


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
    cycle: int              # 71, 70 or 0


@dataclass(frozen=True)
class ProfileBlock:
    element: Element
    rapid: bool
    feed: float             # mm/s (0: none in force)
    line: int
    raw: str                # the block as written (for messages)


@dataclass(frozen=True)
class Profile:
    """The profile N<P>..N<Q>: the first block's move from the start point, then the part's outline."""

    p: int
    q: int
    lead: ProfileBlock              # the N<P> block: S -> A, in X only
    blocks: tuple[ProfileBlock, ...]
    pocket: int = 0                 # the line where X first falls along -Z (type II), 0: monotone (type I)

    @property
    def elements(self) -> list[Element]:
        return [b.element for b in self.blocks]


@dataclass
class _Modes:
    motion: int | None = None
    incremental: bool = False
    diameter: bool = False
    feed: float = 0.0       # mm/s


@dataclass
class _Block:
    line: int
    raw: str
    words: list[tuple[str, float, str, int]]
    n: int | None

    def col(self, letter: str) -> int:
        return next((c for w, _, _, c in self.words if w == letter), 1)

    def err(self, col: int, reason: str) -> ProgramError:
        return ProgramError(self.line, col, self.raw.strip(), reason)


# -- reading the blocks -------------------------------------------------------------------------------
def _blocks(text: str) -> list[_Block]:
    lines = program_lines(text)
    out: list[_Block] = []
    numbered: dict[int, int] = {}           # block number -> line
    ended_at = 0
    for n, raw in enumerate(lines, start=1):
        if raw.strip() == "%":
            continue
        clean = strip_comments(raw, n)
        if ended_at:
            if clean.strip():
                raise ProgramError(n, len(clean) - len(clean.lstrip()) + 1, raw.strip(),
                                   f"text after the program end (line {ended_at})")
            continue
        block = words(clean, n)
        if not block:
            continue
        number = None
        seen: dict[str, int] = {}
        for i, (letter, value, spelled, col) in enumerate(block):
            check_once(seen, i, letter, col, n, raw)
            if letter == "N":
                if value != int(value) or value < 0:
                    raise ProgramError(n, col, raw.strip(), f"N{spelled}: a block number is a whole number >= 0")
                number = int(value)
                if number in numbered:
                    raise ProgramError(n, col, raw.strip(), f"N{number} again: line {numbered[number]} is N{number} "
                                                            "(a block number names one block: G70/G71 P and Q "
                                                            "find the profile by it)")
                numbered[number] = n
            elif letter == "M":
                if value not in (2, 30):
                    raise ProgramError(n, col, raw.strip(), f"M{spelled} is not in the subset (M02, M30)")
                ended_at = n
        out.append(_Block(n, raw, block, number))
    if not ended_at:
        last = max((n for n, line in enumerate(lines, start=1) if line.strip()), default=1)
        raise ProgramError(last, 1, lines[last - 1].strip(), "the program does not end with M02 or M30")
    return out


def _r_centre(b: _Block, start: Point, end: Point, r: float, ccw: bool) -> Point:
    """The centre of an R-format arc (RS274/NGC: R > 0 at most half a circle, R < 0 more)."""
    dz, dx = end[0] - start[0], end[1] - start[1]
    chord = math.hypot(dz, dx)
    if chord <= EPS:
        raise b.err(b.col("R"), "an R-format arc needs an end point apart from its start (a full circle needs I/K)")
    half = chord / 2.0
    if abs(r) < half - ARC_RADIUS_TOLERANCE:
        raise b.err(b.col("R"), f"R{r:g} does not define a circle: start and end are {chord:.4f} mm apart, more "
                                f"than the diameter {2 * abs(r):g} mm")
    along = math.sqrt(max(r * r - half * half, 0.0))
    nz, nx = -dx / chord, dz / chord                  # left of the chord's direction
    side = (1.0 if ccw else -1.0) * (1.0 if r > 0 else -1.0)
    return (start[0] + dz / 2 + side * along * nz, start[1] + dx / 2 + side * along * nx)


def _move(b: _Block, modes: _Modes, here: Point, values: dict[str, float],
          new_motion: int | None, motion_col: int | None, profile: bool) -> tuple[Element | None, Point]:
    """The element of a move block from ``here`` ((z, x)), and its end point."""
    motion = new_motion if new_motion is not None else modes.motion
    has_end = "X" in values or "Z" in values
    has_centre = "I" in values or "K" in values
    if has_centre and motion not in (2, 3):
        raise b.err(b.col("I") if "I" in values else b.col("K"), "I and K belong to G02/G03 arcs")
    if "R" in values and motion not in (2, 3):
        raise b.err(b.col("R"), "R outside G71 is an arc radius: it belongs to G02/G03")
    if not (has_end or has_centre or "R" in values):
        return None, here
    xz_col = min((b.col(k) for k in "XZ" if k in values), default=1)
    if motion is None:
        raise b.err(xz_col, "a move with no motion mode: give G00, G01, G02 or G03 first")
    move_col = motion_col or xz_col
    if motion != 0 and modes.feed == 0.0 and not profile:   # a profile's feed is its cycle's (checked there)
        raise b.err(move_col, f"G{motion:02d} with no feed: give F (mm/min) first")
    scale = 0.5 if modes.diameter else 1.0
    z, x = here
    tz = z + values.get("Z", 0.0) if modes.incremental else values.get("Z", z)
    tx = x + scale * values.get("X", 0.0) if modes.incremental else (scale * values["X"] if "X" in values else x)
    if max(abs(tz), abs(tx)) > COORDINATE_LIMIT:
        raise b.err(xz_col, f"the move ends at X {tx:g}, Z {tz:g}: beyond {COORDINATE_LIMIT:g} mm")
    end = (tz, tx)
    if motion in (2, 3):
        ccw = motion == 3
        if has_centre and "R" in values:
            raise b.err(b.col("R"), "give the arc's centre (I/K) or its radius (R), not both")
        if "R" in values:
            centre = _r_centre(b, here, end, values["R"], ccw)
        elif has_centre:
            centre = (z + values.get("K", 0.0), x + values.get("I", 0.0))
        else:
            raise b.err(move_col, f"G{motion:02d} needs the centre as I/K or the radius as R")
        r0, r1 = math.dist(here, centre), math.dist(end, centre)
        ccol = b.col("R") if "R" in values else min(b.col(k) for k in "IK" if k in values)
        if r0 < ARC_RADIUS_TOLERANCE:
            raise b.err(ccol, "the centre is the start point: this arc does not define a circle")
        if abs(r0 - r1) > ARC_RADIUS_TOLERANCE:
            raise b.err(ccol, f"I/K do not define a circle through start and end: radius {r0:.4f} mm to the start, "
                              f"{r1:.4f} mm to the end (tolerance {ARC_RADIUS_TOLERANCE:g} mm)")
        if math.dist(here, end) <= EPS:
            end = here
        arc = arc_through(here, end, centre, ccw, ARC_RADIUS_TOLERANCE)
        return arc, arc.end if math.dist(arc.end, end) > 1e-12 else end
    if math.dist(here, end) <= EPS:
        return None, end
    return Line(here, end), end


@dataclass
class _Cycle:
    code: int
    block: _Block
    values: dict[str, float]


def _interpret(b: _Block, modes: _Modes, here: Point,
               profile: bool = False) -> tuple[Element | None, Point, bool, _Cycle | None]:
    """Apply one block's modes; its move (or None), end point, rapid flag and canned cycle (or None)."""
    groups: dict[str, int] = {}
    values: dict[str, float] = {}
    new_motion, motion_col, cycle = None, None, None
    for letter, value, spelled, col in b.words:
        word = f"{letter}{spelled}"
        if letter in "NM":
            continue
        if letter == "G":
            if value != int(value) or value > 99:
                raise b.err(col, f"{word} is not in the subset")
            g = int(value)
            if g in _REFUSED_G:
                raise b.err(col, f"{word}: {_REFUSED_G[g]}")
            if g not in _GROUPS:
                raise b.err(col, f"{word} is not in the subset (G00-G03, G7, G8, G18, G21, G70, G71, G90, G91)")
            group = _GROUPS[g]
            if group in groups:
                raise b.err(col, f"G{groups[group]:02d} and {word} in one block: both belong to the modal group "
                                 f"{group}")
            groups[group] = g
            if g in _MOTION:
                new_motion, motion_col = g, col
            elif g in (90, 91):
                modes.incremental = g == 91
            elif g in (7, 8):
                modes.diameter = g == 7
            elif g in (70, 71):
                cycle = g
            continue
        if letter == "F":
            if not value > 0:
                raise b.err(col, f"{word}: the feed must be > 0 mm/min")
            values["F"] = value
            continue
        if letter in "XZIKRUWPQ":
            if abs(value) > COORDINATE_LIMIT:
                raise b.err(col, f"{word}: beyond {COORDINATE_LIMIT:g} mm, no machine is that large")
            values[letter] = value
            continue
        reason = ("the lathe subset has no Y axis (XZ plane)" if letter == "Y" else
                  "tool nose radius compensation is not in the subset" if letter == "D" else
                  f"word {letter} is not in the subset (G, M, N, X, Z, I, K, R, F, U, W, P, Q)")
        raise b.err(col, f"{word}: {reason}")
    if "F" in values:
        modes.feed = values["F"] / 60.0                # modal, a cycle's F too (RS274)
    if cycle is not None:
        if new_motion is not None:
            raise b.err(motion_col or 1, f"G{new_motion:02d} and G{cycle} in one block: a canned cycle moves by "
                                         "itself")
        for k in "XZIK":
            if k in values:
                raise b.err(b.col(k), f"{k}: G{cycle} takes P, Q, U, W, R and F (the profile is in N<P>..N<Q>)")
        return None, here, False, _Cycle(cycle, b, values)
    for k in "UWPQ":
        if k in values:
            reason = ("U and W as incremental X/Z are not in the subset: use G91" if k in "UW" else
                      "P and Q belong to G70/G71")
            raise b.err(b.col(k), f"{k}{values[k]:g}: {reason}")
    element, end = _move(b, modes, here, values, new_motion, motion_col, profile)
    if new_motion is not None:
        modes.motion = new_motion
    return element, end, modes.motion == 0, None


# -- the program ------------------------------------------------------------------------------------
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


@dataclass(frozen=True)
class Finish:
    """A G70 cycle from ``start`` ((z, x)) along ``profile`` (``feed`` mm/s overrides the blocks' own; 0: none)."""

    line: int
    start: Point
    profile: Profile
    feed: float


@dataclass(frozen=True)
class Move:
    element: Element
    rapid: bool
    feed: float
    line: int


Op = Move | Rough | Finish


def _whole(b: _Block, values: dict[str, float], letter: str, code: int) -> int:
    if letter not in values:
        raise b.err(1, f"G{code} P Q: {letter} (the {'first' if letter == 'P' else 'last'} block number of the "
                       "profile) is missing")
    v = values[letter]
    if v != int(v) or v < 0:
        raise b.err(b.col(letter), f"{letter}{v:g}: a block number is a whole number >= 0")
    return int(v)


def _read_profile(blocks: list[_Block], i: int, b: _Block, p: int, q: int, modes: _Modes,
                  start: Point, code: int) -> tuple[Profile, int]:
    """The profile N<p>..N<q> that starts at ``blocks[i]`` (it must), and the index after N<q>."""
    if i >= len(blocks) or blocks[i].n != p:
        where = [x.line for x in blocks if x.n == p]
        reason = (f"P{p}: the profile's first block N{p} is not in the program" if not where else
                  f"P{p}: N{p} (line {where[0]}) must follow the G{code} block directly (Fanuc's form)")
        raise b.err(b.col("P"), reason)
    if not any(x.n == q for x in blocks[i:]):
        raise b.err(b.col("Q"), f"Q{q}: the profile's last block N{q} is not in the program after N{p}")
    saved = replace(modes)
    here = start
    pieces: list[ProfileBlock] = []
    j = i
    while True:
        blk = blocks[j]
        if any(w[0] == "M" for w in blk.words):
            raise blk.err(blk.col("M"), f"the program ends inside the profile N{p}..N{q}")
        element, end, rapid, cycle = _interpret(blk, modes, here, profile=True)
        if cycle is not None:
            raise blk.err(blk.col("G"), f"G{cycle.code} inside the profile N{p}..N{q}")
        if j == i:
            if element is None or isinstance(element, Arc) or abs(end[0] - start[0]) > EPS:
                raise blk.err(1, f"the profile's first block N{p} must move in X only from the start point "
                                 f"(X {start[1]:g}, Z {start[0]:g}) to the profile's start (Fanuc's form)")
            lead = ProfileBlock(element, rapid, modes.feed, blk.line, blk.raw.strip())
        elif element is not None:
            pieces.append(ProfileBlock(element, rapid, modes.feed, blk.line, blk.raw.strip()))
        here = end
        j += 1
        if blk.n == q:
            break
    modes.motion, modes.incremental, modes.diameter, modes.feed = (saved.motion, saved.incremental,
                                                                   saved.diameter, saved.feed)
    if not pieces:
        raise b.err(b.col("Q"), f"the profile N{p}..N{q} has no block after its first (the outline of the part)")
    profile = Profile(p, q, lead, tuple(pieces))
    return replace(profile, pocket=_check_profile(profile, start)), j


def _extreme(arc: Arc, angle: float) -> Point | None:
    """The arc's point in the direction ``angle`` from its centre, if it passes it strictly between its ends."""
    p = (arc.center[0] + arc.radius * math.cos(angle), arc.center[1] + arc.radius * math.sin(angle))
    return p if EPS < arc.param(p) < arc.length - EPS else None


def _check_profile(profile: Profile, start: Point) -> int:
    """Toward -Z all along, inside the stock (below the start point's X, above the axis); returns the line where X
    first falls along -Z (a pocket or undercut: type II), 0 if it never does (type I)."""
    pocket = 0
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
            raise ProgramError(line, 1, raw, f"the profile leaves the stock: X {top:.6g} above the start "
                                                        f"point's X {start[1]:g}")
        bottom = min(s[1], t[1], x_lo[1] if x_lo else math.inf)
        if bottom < -TOL:
            raise ProgramError(line, 1, raw, f"the profile crosses the spindle axis: X {bottom:.6g} < 0")
    if profile.blocks[-1].element.end[0] >= start[0] - TOL:
        last = profile.blocks[-1]
        raise ProgramError(last.line, 1, last.raw, "the profile ends in front of the start point's Z: nothing to cut")
    return pocket


def parse(text: str, start: tuple[float, float]) -> list[Op]:
    """The operations of a lathe program; the tool starts at ``start`` = (x, z).

    Raises
    ------
    ProgramError
        naming the line, the column and the reason, for the first thing outside the subset or wrong.
    """
    blocks = _blocks(text)
    modes = _Modes()
    here: Point = (start[1], start[0])
    ops: list[Op] = []
    profiles: dict[tuple[int, int], Profile] = {}
    g71_first: tuple[float, float] | None = None
    i = 0
    while i < len(blocks):
        b = blocks[i]
        i += 1
        element, end, rapid, cycle = _interpret(b, modes, here)
        if element is not None:
            ops.append(Move(element, rapid, modes.feed, b.line))
        here = end
        if cycle is None:
            continue
        v = cycle.values
        if cycle.code == 71 and "P" not in v and "Q" not in v:
            if "U" not in v or "R" not in v:
                raise b.err(1, "G71's first block gives the depth of cut U and the retract R (radius values)")
            if not v["U"] > 0:
                raise b.err(b.col("U"), f"U{v['U']:g}: the depth of cut must be > 0")
            if v["R"] < 0:
                raise b.err(b.col("R"), f"R{v['R']:g}: the retract must be >= 0")
            for k in "WF":
                if k in v:
                    raise b.err(b.col(k), f"{k}: belongs to G71's second block (G71 P Q U W F)")
            g71_first = (v["U"], v["R"])
            continue
        p, q = _whole(b, v, "P", cycle.code), _whole(b, v, "Q", cycle.code)
        if cycle.code == 70:
            for k in "UWR":
                if k in v:
                    raise b.err(b.col(k), f"{k}: G70 takes P, Q and F")
        elif "R" in v:
            raise b.err(b.col("R"), "R: the retract belongs to G71's first block (G71 U R)")
        feed = v["F"] / 60.0 if "F" in v else 0.0
        if i < len(blocks) and blocks[i].n == p:
            profile, i = _read_profile(blocks, i, b, p, q, modes, here, cycle.code)
            profiles[(p, q)] = profile
        elif (p, q) in profiles:
            profile = profiles[(p, q)]
            (z1, x1) = profile.lead.element.start
            if cycle.code == 71 and math.dist((z1, x1), here) > EPS:
                raise b.err(b.col("P"), f"P{p}: the profile N{p}..N{q} was read from the start point X {x1:g} Z "
                                        f"{z1:g}, this G71 starts at X {here[1]:g} Z {here[0]:g}")
        else:
            profile, _ = _read_profile(blocks, i, b, p, q, modes, here, cycle.code)   # raises: not found
        if cycle.code == 70:
            if feed == 0.0:
                for pb in (profile.lead, *profile.blocks):
                    if not pb.rapid and pb.feed == 0.0:
                        raise b.err(1, f"G70: the profile's block on line {pb.line} has no feed: give F")
            ops.append(Finish(b.line, here, profile, feed))
            continue
        if g71_first is None:
            raise b.err(1, "G71 P Q needs G71's first block (G71 U<depth> R<retract>) before it")
        u = v.get("U", 0.0) * (0.5 if modes.diameter else 1.0)
        w = v.get("W", 0.0)
        if u < 0 or w < 0:
            k = "U" if u < 0 else "W"
            raise b.err(b.col(k), f"{k}{v[k]:g}: a negative allowance would cut into the part (outside roughing only)")
        if profile.pocket and w > 0:
            raise b.err(b.col("W"), f"W{w:g}: the profile has a pocket (X falls along -Z on line {profile.pocket}): "
                                    "a Z allowance would shift its near wall into the part; give W0 (type II is "
                                    "roughed with the X allowance U alone)")
        feed = feed or modes.feed
        if profile.blocks[-1].element.end[0] + w >= here[0] - TOL:
            raise b.err(b.col("W"), f"W{w:g}: the profile shifted by the Z allowance ends in front of the start "
                                    "point's Z: nothing to cut")
        if feed == 0.0:
            raise b.err(1, "G71 with no feed: give F (mm/min) here or before")
        rough = Rough(b.line, here, profile, g71_first[0], g71_first[1], u, w, feed)
        low = min(min(e.start[1], e.end[1]) for e in monotone_pieces(rough_boundary(rough)))
        if low >= here[1] - TOL:
            raise b.err(b.col("U"), f"U{v.get('U', 0.0):g}: the profile shifted by the allowance lies nowhere below "
                                    f"the start point's X {here[1]:g} (its lowest X {low:g}): nothing to rough, and "
                                    "G70 would take the whole depth in one pass")
        ops.append(rough)
    if not ops:
        raise ProgramError(blocks[-1].line, 1, blocks[-1].raw.strip(), "the program has no moves")
    return ops


# -- planning the cycles ----------------------------------------------------------------------------
def shifted(e: Element, dz: float, dx: float) -> Element:
    if isinstance(e, Line):
        return Line((e.start[0] + dz, e.start[1] + dx), (e.end[0] + dz, e.end[1] + dx))
    return Arc((e.center[0] + dz, e.center[1] + dx), e.radius, e.a0, e.sweep)


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
    return clip_front([shifted(e, op.w, op.u) for e in op.profile.elements], op.start[0])


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
    lines = [pb.line for pb in op.profile.blocks]
    return lines[len(lines) - len(bound):]


def _plan_finish(op: Finish, rapid: float) -> list[Segment]:
    out: list[Segment] = []
    z0, x0 = op.start
    a = op.profile.lead.element.end
    lead = op.profile.lead

    def rate(pb: ProfileBlock) -> tuple[float, bool]:
        return (rapid, False) if pb.rapid else (op.feed or pb.feed, True)

    r, f = rate(lead)
    out.append(Segment(Line(op.start, a), r, f, 1, 1, 0.0, lead.line, 70))
    for pb in op.profile.blocks:
        r, f = rate(pb)
        out.append(Segment(pb.element, r, f, 2, 1, 0.0, pb.line, 70))
    bz, bx = op.profile.blocks[-1].element.end
    clear = max(x0, bx)
    # up the wall the profile ends at, at the feed: below the stock's X the roughing left its allowance there
    up = op.feed or op.profile.blocks[-1].feed
    out.append(Segment(Line((bz, bx), (bz, clear)), up or rapid, up > 0, 3, 1, 0.0, op.line, 70))
    out.append(Segment(Line((bz, clear), (z0, clear)), rapid, False, 4, 1, 0.0, op.line, 70))
    if clear > x0:
        out.append(Segment(Line((z0, clear), op.start), rapid, False, 0, 0, 0.0, op.line, 70))
    return out


def plan_ops(ops: list[Op], rapid: float) -> list[Segment]:
    out: list[Segment] = []
    for op in ops:
        if isinstance(op, Move):
            out.append(Segment(op.element, rapid if op.rapid else op.feed, not op.rapid, 0, 0, 0.0, op.line, 0))
        elif isinstance(op, Rough):
            out += _plan_rough(op, rapid)
        else:
            out += _plan_finish(op, rapid)
    return out


def plan(text: str, start: tuple[float, float], rapid: float) -> list[Segment]:
    """Every move of a program (the tool at ``start`` = (x, z)), G00 and the cycles' rapids at ``rapid`` mm/s."""
    return plan_ops(parse(text, start), rapid)


# -- motion along a line or an arc ------------------------------------------------------------------
class ElementMove(LinearMove):
    """:class:`.motion.LinearMove`'s online speed profile along a line or an arc of the (z, x) plane; positions
    and velocities in (x, z). On an arc the tangential acceleration is ``ARC_TANGENTIAL * accel`` and the speed
    at most ``sqrt(ARC_CENTRIPETAL * accel * R)``, so the vector acceleration stays below ``accel``."""

    def __init__(self, accel: float) -> None:
        super().__init__(accel)
        self.full_accel = accel
        self.arc: Arc | None = None

    def begin(self, start: tuple[float, ...], end: tuple[float, ...], rate: float) -> None:
        self.arc = None
        self.accel = self.full_accel
        super().begin(start, end, rate)

    @staticmethod
    def rate_on(element: Element, rate: float, accel: float) -> float:
        """The rate a move along ``element`` runs at: ``rate``, on an arc at most its centripetal cap."""
        if isinstance(element, Arc):
            return min(rate, math.sqrt(ARC_CENTRIPETAL * accel * element.radius))
        return rate

    def begin_element(self, element: Element, rate: float) -> None:
        self.begin(xz(element.start), xz(element.end), rate)
        if isinstance(element, Arc):
            self.arc = element
            self.length = element.length
            self.done = self.length == 0.0
            self.accel = ARC_TANGENTIAL * self.full_accel
            self.rate = self.rate_on(element, rate, self.full_accel)

    def _end_here(self) -> None:
        """Halted on an arc: the move ends where it rests, a straight move of no length from then on."""
        super()._end_here()
        self.arc = None
        self.accel = self.full_accel

    def position(self) -> tuple[float, ...]:
        if self.arc is None or self.done:
            return super().position()
        return xz(self.arc.point(self.s))

    def velocity(self) -> tuple[float, ...]:
        if self.arc is None or self.done:
            return super().velocity()
        tz, tx = self.arc.tangent(self.s)
        return (tx * self.v, tz * self.v)
