"""Lathe part programs in the Fanuc 0i-T dialect (G code system A, mm) with G71 stock removal and G70
finishing, planned as the seed's sub-cycles (US 4,017,723: SC1 infeed, SC2 cut, SC3 retract, SC4 return).

Words (one block per line, letters in either case; the README has the table)::

    % (tape)   O program number   N block number   ( comment )   ; comment to the end of the line
    G00 rapid   G01 line   G02 clockwise arc   G03 counter-clockwise arc        (motion, modal)
    X Z end point (X a diameter: Setup.diameter, seq.x_diameter)   U W incremental X (diameter) / Z
    I K arc centre relative to the arc's start (radius values)   R arc radius
    G7 X is a diameter   G8 X is a radius   G18 XZ plane   G21 mm   G90/G91     (modal)
    G40 / G41 / G42 tool-nose radius compensation off / left / right (:mod:`.nose`; G71 roughs uncompensated)
    /  block delete at a block's start (skipped with Setup.block_delete, seq.block_delete at START)
    G04 P<ms> | X/U<s> dwell   G28 X/U Z/W reference return via the intermediate point   G50 S<max rev/min>
    G96 S<m/min> | G97 S<rev/min>   G98 F mm/min | G99 F mm/rev (Setup.feed_per_rev)   T<tool><offset>
    M03/M04/M05 spindle   M08/M09 coolant   M00/M01 stops   M02/M30 program end
    G71 U<depth of cut> R<retract>                first block: radius values
    G71 P<first N> Q<last N> U<X allowance> W<Z allowance> [F]  second block: U in the X mode in force
                                                (U <= 0 for a bore: a profile rising from the start point)
    G70 P<first N> Q<last N> [F]                  one pass along the profile
    G72 W<depth> R<retract> / G72 P Q U W [F]     facing stock removal, G73 U<escape X> W<escape Z> R<passes> /
                                                G73 P Q U W [F] pattern repeat (:mod:`.g72_g73`)
    G90 X/U Z/W [R] F | G94 X/U Z/W [R] F       single cycles: turning / facing, one pass (:mod:`.single_cycles`);
                                                G90 with X/Z and no G00-G03 in its block (else the absolute mode)
    G32 / G92 / G76                               threads (:mod:`.thread_cycles`)
    G54..G59 work offsets (Setup.works, seq.work[k])   M98 P<repeats><program> [L] / M99 [P]  subprograms
                                                (:mod:`.subprograms`: O programs after M30, ending with M99)
    ,C<chamfer> ,R<radius> between two G01 moves; A<angle> on G01   (:mod:`.direct_dimensions`)
    G74 R<retract> / G74 X/U Z/W P<step, um> Q<peck, um> R<relief> F  face peck drilling (on the axis with a drill)
    G75 R<retract> / G75 X/U Z/W P<peck, um> Q<step, um> R<relief> F  grooving     (:mod:`.peck_cycles`)

Positions are the programmed tool tip; the axes carry the active work and tool offsets (:func:`.g7x.plan_ops`). The
machine words become :class:`.g7x.State` operations: each planned move runs with its :class:`.g7x.Modal`.

Geometry: elements (:class:`.geometry.Line`, :class:`.geometry.Arc`) in the **(z, x) plane** -- first
coordinate Z (to the right), second X (the radius, up), as a lathe drawing shows the part. Seen from +Y,
RS274/NGC's G02 is clockwise with Z to the right and X up, so G02 is a clockwise arc of the geometry (negative
sweep) and G03 a counter-clockwise one. The controller's commands are (x, z): :func:`xz` turns a point round.

Reading and checking are the one front end's (:mod:`.gcode`, with the dialect :data:`LATHE` here: every
reading error of a program at once, in line order); this module converts the blocks to moves (the modes, the
positions, arcs by I/K or R) and reads the profile of each cycle; the cycles' geometry and planning are
:mod:`.g7x`'s.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

from ..errors import ProgramError
from .direct_dimensions import DimensionError, angled_end, corner
from .g7x import (  # noqa: F401  (the cycles' records, named here too: a lathe program's operations)
    EPS,
    MAX_SEGMENTS,
    NO_MODAL,
    TOL,
    Dwell,
    Finish,
    Home,
    Modal,
    Op,
    PeckCycle,
    PlannedCycle,
    Profile,
    Rough,
    Segment,
    SingleCycle,
    State,
    Stop,
    Thread,
    Tool,
    check_profile,
    finish_path,
    mirror_op,
    mirror_profile,
    monotone_pieces,
    plan_ops,
    rough_boundary,
)
from .g72_g73 import FirstBlock, face_finish, face_rough, first_block, first_block_error, pattern_repeat
from .g72_g73 import check_profile as check_face_or_pattern
from .gcode import (
    ARC_RADIUS_TOLERANCE,
    COMP_SIDE,
    COORDINATE_LIMIT,
    Block,
    Dialect,
    Modes,
    Move,
    arc,
    program_lines,
    read,
    strip_comments,
)
from .geometry import Arc, CornerError, Element, Line, Point
from .mypyc_compat import mypyc_attr
from .nose import Nose
from .peck_cycles import PeckError, plan_pecks, region
from .single_cycles import CycleError, plan_single
from .subprograms import run_order
from .thread_cycles import G76Setup, ThreadError, g76_setup, plan_g32, plan_g76, plan_g92

_MOTION = {0, 1, 2, 3}
_WORK = range(54, 60)       # G54..G59: the work offsets seq.work[1..6]
#: The G codes a G70/G71 profile may not hold (the machine's state, not the part's outline). A set made once:
#: mypyc (the compiled controllers) cannot compile a starred range inside a tuple display.
_NOT_IN_PROFILE = frozenset({4, 28, 40, 41, 42, 50, *_WORK, 96, 97, 98, 99})
#: Fanuc's group 00 codes here: one-shot, their own block's meaning -- their U/W (G28 U0 W0, G71 U1.5 R0.5,
#: G72 P Q U W, G73 U3 W1 R3, G04 U1.5) never make the next pass of a modal G90/G94/G92/G32.
_ONE_SHOT = frozenset({4, 28, 50, 70, 71, 72, 73})
#: The lathe's words: a Fanuc 0i-T programmer's (G code system A), and RS274's G7/G8/G90/G91/G18/G21.
_THREAD_MOTION = (32, 92)
LATHE = Dialect(
    name="lathe",
    groups={**{g: "motion (G00-G03, G32, G92, G94)" for g in (*_MOTION, *_THREAD_MOTION, 94)}, 18: "plane (G18)",
            21: "units (G21)",
            90: "distance mode (G90/G91)", 91: "distance mode (G90/G91)", 7: "X mode (G7/G8)", 8: "X mode (G7/G8)",
            **{g: "canned cycle (G70-G76)" for g in (70, 71, 72, 73, 74, 75, 76)},
            4: "non-modal (G04, G28, G50)", 28: "non-modal (G04, G28, G50)", 50: "non-modal (G04, G28, G50)",
            **{g: "tool-nose radius compensation (G40-G42)" for g in (40, 41, 42)}, 96: "spindle speed mode (G96/G97)",
            97: "spindle speed mode (G96/G97)", 98: "feed mode (G98/G99)", 99: "feed mode (G98/G99)",
            **{g: "work offset (G54-G59)" for g in range(54, 60)}},
    refused_g={17: "a lathe works in the XZ plane (G18)", 19: "a lathe works in the XZ plane (G18)",
               20: "inch units are not in the subset: write the program in mm (G21)"},
    g_list="G00-G03, G04, G7, G8, G18, G21, G28, G32, G40-G42, G50, G54-G59, G70-G76, G90, G91, G92, G94, "
           "G96-G99",
    m_codes=frozenset({0, 1, 2, 3, 4, 5, 8, 9, 30, 98, 99}),
    m_list="M00, M01, M02, M03, M04, M05, M08, M09, M30, M98, M99",
    coordinates="XZIKRUWPQSTOLA",
    refused_letters={"Y": "the lathe subset has no Y axis (XZ plane)",
                     "D": "tool nose radius compensation is not in the subset"},
    letter_list="G, M, N, O, X, Z, U, W, I, K, R, F, S, T, P, Q, L, A, ,C, ,R",
    unique_numbers=True,
    block_delete=True,
    subprograms=True,
    comma_letters="CR",
    axes=(("Z", "W"), ("X", "U")),
)


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Setup:
    """What a lathe program is read with besides its text: the sequencer's parameters."""

    diameter: bool = True                 # X is a diameter until G7/G8 (seq.x_diameter; Fanuc's lathes)
    feed_per_rev: bool = False            # G99 until G98/G99 (seq.feed_per_rev)
    tools: tuple[Tool, ...] = (Tool(),) * 8   # the tool table, offset k = tools[k - 1] (seq.tool[1..8])
    home: Point | None = None             # the machine reference (z, x) for G28 (seq.z_home, seq.x_home)
    block_delete: bool = False            # the block-delete switch: blocks starting with '/' are skipped
    works: tuple[Point, ...] = ((0.0, 0.0),) * 6   # the work offsets G54..G59 (z, x radius) (seq.work[1..6])


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass
class _Modes(Modes):
    """The one conversion's modes (:class:`.gcode.Modes`: motion, G90/G91, G7/G8, F, the tool-nose radius
    compensation's side) and the lathe's machine state besides."""

    machine: Modal = field(default_factory=Modal)
    row: Tool = field(default_factory=Tool)   # the tool table's row of the active offset (its nose)
    row_no: int = 0         # that row's number k (seq.tool[k]; 0: no offset)
    work: Point = (0.0, 0.0)    # the active work offset (z, x radius): G54..G59
    lead: float = 0.0       # a thread block's F (G32/G92/G76): the lead, mm; modal among thread blocks
    cycle_end: Point | None = None  # the modal G92/G90/G94's end (z, x) and taper R: a block with X (or Z) alone
                                    # repeats it
    cycle_taper: float = 0.0
    cycle_pass: int = 0     # passes of the modal G92/G90/G94 so far
    g76: G76Setup | None = None     # G76's first block
    peck_retract: float | None = None   # G74/G75's first block: the retract e after each peck (mm)
    thread_moves: int = 0   # the threads' planned moves so far (at most MAX_SEGMENTS in a program)


def _r_centre(b: Block, start: Point, end: Point, r: float, ccw: bool) -> Point:
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


def _move(b: Block, modes: _Modes, here: Point, values: dict[str, float],
          new_motion: int | None, motion_col: int | None, profile: bool) -> tuple[Element | None, Point]:
    """The element of a move block from ``here`` ((z, x)), and its end point."""
    motion = new_motion if new_motion is not None else modes.motion
    for absolute, incremental in (("X", "U"), ("Z", "W")):
        if absolute in values and incremental in values:
            raise b.err(b.col(incremental), f"{absolute} and {incremental} in one block: give the end point as "
                                            f"{absolute} (absolute) or {incremental} (incremental)")
    values = {**values, **{a: values[inc] for a, inc in (("X", "U"), ("Z", "W")) if inc in values}}
    has_end = "X" in values or "Z" in values
    has_centre = "I" in values or "K" in values
    if has_centre and motion not in (2, 3):
        raise b.err(b.col("I") if "I" in values else b.col("K"), "I and K belong to G02/G03 arcs")
    if "R" in values and motion not in (2, 3):
        raise b.err(b.col("R"), "R outside G71 is an arc radius: it belongs to G02/G03")
    if "A" in values:
        if motion != 1:
            raise b.err(b.col("A"), f"A{values['A']:g} (the move's angle) belongs to G01 moves")
        if ("X" in values) == ("Z" in values):
            raise b.err(b.col("A"), f"A{values['A']:g}: give X (or U) or Z (or W) with the angle, one of them (the "
                                    "angle fixes the other)")
    if not (has_end or has_centre or "R" in values):
        return None, here
    xz_col = min((b.col(k if k in b.values else {"X": "U", "Z": "W"}[k]) for k in "XZ" if k in values), default=1)
    if motion is None:
        raise b.err(xz_col, "a move with no motion mode: give G00, G01, G02 or G03 first")
    move_col = motion_col or xz_col
    if motion in _THREAD_MOTION:
        raise b.err(move_col, f"G{motion} (a thread) inside a profile: the profile's moves are G00-G03")
    if motion != 0 and modes.feed == 0.0 and not profile:   # a profile's feed is its cycle's (checked there)
        raise b.err(move_col, f"G{motion:02d} with no feed: give F (mm/min) first")
    z, x = here
    tz, tx = modes.end(b, here, LATHE.axes)
    if "A" in values:
        try:
            tz, tx = angled_end(here, values["A"], tx if "X" in values else None, tz if "Z" in values else None)
        except DimensionError as err:
            raise b.err(b.col(err.word), err.reason) from None
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
        ccol = b.col("R") if "R" in values else min(b.col(k) for k in "IK" if k in values)
        return arc(b, here, end, centre, ccw, ccol, "R" if "R" in values else "I/K")
    if math.dist(here, end) <= EPS:
        return None, end
    return Line(here, end), end


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass
class _Cycle:
    code: int
    block: Block
    values: dict[str, float]


def _interpret(b: Block, modes: _Modes, here: Point,
               profile: bool = False) -> tuple[Element | None, Point, bool, _Cycle | None]:
    """Apply one block's modes; its move (or None), end point, rapid flag and canned cycle (or None)."""
    values = b.values
    new_motion, motion_col, cycle = None, None, None
    modes.distance_and_x(b)
    for g, col in b.g:
        if g in _MOTION:
            new_motion, motion_col = g, col
        elif g in (70, 71, 72, 73):
            cycle = g
        elif g in _THREAD_MOTION or g == 76:
            raise b.err(col, f"G{g} (a thread) inside a profile: the profile's moves are G00-G03")
        elif g in _PECK:
            raise b.err(col, f"G{g} (a peck cycle) inside a profile: the profile's moves are G00-G03")
        elif g == 94:
            raise b.err(col, f"G{g} (a single cycle) inside a profile: the profile's moves are G00-G03")
        elif g in COMP_SIDE and not profile:
            modes.comp = COMP_SIDE[g]
    modes.feed_word(b)
    if cycle is not None:
        if new_motion is not None:
            raise b.err(motion_col or 1, f"G{new_motion:02d} and G{cycle} in one block: a canned cycle moves by "
                                         "itself")
        for k in ("X", "Z", "I", "K", *_DIMENSION_WORDS):
            if k in values:
                raise b.err(b.col(k), f"{k}: G{cycle} takes P, Q, U, W, R and F (the profile is in N<P>..N<Q>)")
        return None, here, False, _Cycle(cycle, b, values)
    for k in "PQ":
        if k in values:
            raise b.err(b.col(k), f"{k}{values[k]:g}: P and Q belong to G70/G71, G74/G75 and G76 (and P to G04)")
    element, end = _move(b, modes, here, values, new_motion, motion_col, profile)
    if new_motion is not None:
        modes.motion = new_motion
    return element, end, modes.motion == 0, None


# -- the machine: tools, spindle, coolant, dwell, stops, reference return ------------------------------
_BEFORE_MOVE = {3: 1, 4: -1}          # M03/M04 start the spindle before the block's move (M05 stops it after)


def _machine(b: Block, modes: _Modes, setup: Setup) -> None:
    """The block's words that set the machine's state before its move: G50 S, S, G96/G97, G98/G99, T, M03/M04,
    M08 (Fanuc runs them with the move's start)."""
    m, v = modes.machine, b.values
    codes = {g for g, _ in b.g}
    if 50 in codes:
        for k in "XZUW":
            if k in v:
                raise b.err(b.col(k), f"G50 {k}: setting the coordinate system is not in the subset (the program "
                                      "starts where the sequencer's x_start/z_start are)")
        if "S" not in v:
            raise b.err(b.col("G"), "G50 takes S<the highest spindle speed, rev/min> here")
        modes.machine = replace(m, s_max=v["S"])
        return
    if "S" in v:
        if v["S"] < 0:
            raise b.err(b.col("S"), f"S{v['S']:g}: the spindle speed must be >= 0")
        m = replace(m, s=v["S"])
    if 96 in codes:
        if m.s_max <= 0:
            raise b.err(b.col("G"), "G96 needs the highest spindle speed first (G50 S<rev/min>): at the axis the "
                                    "constant surface speed asks for an endless speed")
        m = replace(m, css=True)
    elif 97 in codes:
        m = replace(m, css=False)
    if m.css and "S" in v and v["S"] <= 0:
        raise b.err(b.col("S"), f"S{v['S']:g} under G96: a surface speed of 0 m/min stands the spindle still (a "
                                "feed per revolution would never move): give S > 0")
    if 98 in codes or 99 in codes:
        m = replace(m, per_rev=99 in codes)
    if "T" in v:
        if modes.comp:
            raise b.err(b.col("T"), f"T{v['T']:g} with G4{1 if modes.comp > 0 else 2} in force: cancel the tool-nose "
                                    "radius compensation (G40) before changing the tool or its offset")
        t = v["T"]
        tool, row = divmod(int(t), 100)
        if t != int(t) or t < 0 or not 0 <= tool <= len(setup.tools) or not 0 <= row <= len(setup.tools):
            raise b.err(b.col("T"), f"T{t:g}: T<tool><offset> with tool and offset 0..{len(setup.tools)} (T0101: "
                                    "tool 1 with the offsets of seq.tool[1]; offset 0 cancels the offset)")
        row_tool = setup.tools[row - 1] if row else Tool()
        m = replace(m, tool=tool, offset=(row_tool.z_offset + modes.work[0], row_tool.x_offset + modes.work[1]))
        modes.row, modes.row_no = row_tool, row
    selected = [g for g in codes if g in _WORK]
    if selected:
        modes.work = setup.works[selected[0] - 54]
        m = replace(m, offset=(modes.row.z_offset + modes.work[0], modes.row.x_offset + modes.work[1]))
    for code, _ in b.m:
        if code in _BEFORE_MOVE:
            m = replace(m, spindle=_BEFORE_MOVE[code])
        elif code == 8:
            m = replace(m, coolant=True)
    modes.machine = m


def _after_move(b: Block, modes: _Modes) -> Op | None:
    """The block's words that act after its move: M05, M09, M00/M01 (a stop), M02/M30 (spindle and coolant off)."""
    for code, _ in b.m:
        if code in (0, 1):
            return Stop(b.line, code == 1)
        if code in (5, 9, 2, 30):
            m = modes.machine
            m = replace(m, spindle=0 if code != 9 else m.spindle, coolant=False if code != 5 else m.coolant)
            if m != modes.machine:
                modes.machine = m
                return State(b.line, m)
    return None


def _dwell(b: Block) -> Dwell:
    v = b.values
    given = [k for k in "PXU" if k in v]
    if len(given) != 1:
        raise b.err(b.col("G"), "G04 takes the dwell once: P<ms> or X/U<s>")
    seconds = v["P"] / 1000.0 if given[0] == "P" else v[given[0]]
    if not seconds >= 0:
        raise b.err(b.col(given[0]), f"{given[0]}{v[given[0]]:g}: a dwell is >= 0")
    return Dwell(b.line, seconds)


def _home(b: Block, modes: _Modes, here: Point, setup: Setup) -> Home:
    v = b.values
    if setup.home is None:
        raise b.err(b.col("G"), "G28 needs the machine reference (seq.x_home, seq.z_home)")
    axes = [k for k in "XZUW" if k in v]
    if not axes:
        raise b.err(b.col("G"), "G28 names the axes to return: X/U and/or Z/W (the intermediate point)")
    vz, vx = modes.end(b, here, LATHE.axes)
    return Home(b.line, (vz, vx), (setup.home[0] if "Z" in v or "W" in v else None,
                                   setup.home[1] if "X" in v or "U" in v else None))


# -- threads: G32, G92, G76 (:mod:`.thread_cycles`) ------------------------------------------------------
#: G codes a thread block may hold besides its own: the modes that only say how its X and Z are read.
_THREAD_BLOCK_G = frozenset({7, 8, 18, 21, 90, 91})


def _thread_kind(b: Block, modes: _Modes) -> int:
    """32, 92 or 76 when the block is a thread's (its own G code, or X/U or Z/W under a modal G32 or G92; a block
    with a one-shot code never repeats the modal cycle)."""
    codes = [g for g, _ in b.g]
    if 76 in codes:
        return 76
    if _ONE_SHOT.intersection(codes):
        return 0
    for g in codes:
        if g in _MOTION:
            return 0
        if g in _THREAD_MOTION:
            return g
    if modes.motion in _THREAD_MOTION and any(k in b.values for k in "XZUW"):
        return modes.motion or 0
    return 0


def _check_thread_words(b: Block, kind: int, spindle: bool = True) -> None:
    """The spindle cannot change during a thread (Z follows it): no S, T, G96/G97, M03/M04/M05 in its block; no
    other G code in a thread's or single cycle's block (``spindle`` False: a single cycle's, which may hold S, T
    and M words)."""
    for g, col in b.g:
        if not spindle and g != kind and g not in _THREAD_BLOCK_G:
            raise b.err(col, f"G{g:02d} in a G{kind} block: give it a block of its own")
    if not spindle:
        return
    for k in "ST":
        if k in b.values:
            raise b.err(b.col(k), f"{k} in a thread block (G{kind}): the spindle speed and the tool cannot change "
                                  "during a thread (give G97 S, M03/M04 and T in the blocks before it)")
    for g, col in b.g:
        if g != kind and g not in _THREAD_BLOCK_G:
            raise b.err(col, f"G{g:02d} in a thread block (G{kind}): give it a block of its own")
    for code, col in b.m:
        if code in (3, 4, 5):
            raise b.err(col, f"M{code:02d} in a thread block (G{kind}): the spindle cannot change during a thread")


def _target(b: Block, modes: _Modes, here: Point, z_default: float | None = None) -> Point:
    """The end point of a thread block's X/U and Z/W ((z, x), X a diameter as the X mode says); Z stays
    ``z_default`` (else where the tool is) when the block has no Z/W."""
    v = b.values
    for absolute, incremental in (("X", "U"), ("Z", "W")):
        if absolute in v and incremental in v:
            raise b.err(b.col(incremental), f"{absolute} and {incremental} in one block: give the end point as "
                                            f"{absolute} (absolute) or {incremental} (incremental)")
    tz, tx = modes.end(b, here, LATHE.axes)
    if z_default is not None and "Z" not in v and "W" not in v:
        tz = z_default
    if max(abs(tz), abs(tx)) > COORDINATE_LIMIT:
        raise b.err(1, f"the thread ends at X {tx:g}, Z {tz:g}: beyond {COORDINATE_LIMIT:g} mm")
    return (tz, tx)


def _microns(b: Block, letter: str, what: str) -> float:
    """A G76 word in um (Fanuc writes it without a decimal point), as mm."""
    if letter not in b.values:
        raise b.err(1, f"G76 X Z P Q F: {letter} ({what}, um) is missing")
    value = b.values[letter]
    if value != int(value) or value <= 0:
        raise b.err(b.col(letter), f"{letter}{value:g}: {what} is a whole number of um > 0 (P1227: 1.227 mm)")
    return value / 1000.0


def _thread(b: Block, kind: int, modes: _Modes, here: Point, ops: list[Op]) -> Point:
    """A thread block: G76's first block sets the cycle up; a thread's block adds its :class:`.g7x.Thread`.
    Returns where the tool ends."""
    end = _thread_op(b, kind, modes, here, ops)
    if ops and isinstance(ops[-1], Thread) and ops[-1].line == b.line:
        modes.thread_moves += len(ops[-1].segments)
        if modes.thread_moves > MAX_SEGMENTS:
            raise b.err(1, f"more than {MAX_SEGMENTS} planned thread moves in the program (a least depth Q or "
                           "first depth too small for the thread's height?)")
    return end


def _thread_op(b: Block, kind: int, modes: _Modes, here: Point, ops: list[Op]) -> Point:
    v = b.values
    modes.distance_and_x(b)
    try:
        if kind == 76 and not any(k in v for k in "XZUW"):
            for k in "FIK":
                if k in v:
                    raise b.err(b.col(k), f"{k}: G76's first block takes P(m)(r)(a), Q (least depth, um) and R "
                                          "(finishing allowance, mm)")
            missing = [k for k in "PQR" if k not in v]
            if missing:
                raise b.err(1, f"G76's first block gives P(m)(r)(a), Q(least depth, um) and R(finishing allowance, "
                               f"mm): {', '.join(missing)} missing")
            modes.g76 = g76_setup(v["P"], v["Q"], v["R"])
            return here
        for k in "IK" + ("PQR" if kind == 32 else "PQ" if kind == 92 else ""):
            if k in v:
                raise b.err(b.col(k), f"{k}: G{kind} takes " + {32: "X/U, Z/W and F (the lead)",
                                                                92: "X/U, Z/W, R (taper, radius) and F (the lead)",
                                                                76: "X/U, Z/W, R, P, Q and F"}[kind])
        if modes.comp:
            raise b.err(b.col("G"), f"G{kind} with G4{1 if modes.comp > 0 else 2} in force: cancel the tool-nose "
                                    "radius compensation (G40) before a thread")
        m = modes.machine
        if m.css:
            raise b.err(b.col("G"), f"G{kind} with G96 (constant surface speed) in force: a thread needs a constant "
                                    "spindle speed, give G97 S<rev/min> before it")
        if not m.spindle or m.s <= 0:
            raise b.err(b.col("G"), f"G{kind}: a thread with the spindle stopped (Z follows the spindle): give G97 "
                                    "S<rev/min> and M03/M04 before it")
        if "F" in v:
            modes.lead = v["F"]
        if modes.lead <= 0:
            raise b.err(1, f"G{kind} with no lead: give F (the lead, mm per revolution)")
        if kind == 32:
            end = _target(b, modes, here)
            last = ops[-1] if ops else None
            continues = isinstance(last, Thread) and last.code == 32 and math.dist(last.end, here) <= EPS
            ops.append(Thread(b.line, 32, (plan_g32(here, end, modes.lead, m, b.line, continues),), end))
            modes.motion = 32
            return end
        if kind == 92:
            if "X" not in v and "U" not in v:
                raise b.err(1, "G92: each pass gives the thread's X (or U)")
            new = 92 in {g for g, _ in b.g} or modes.motion != 92
            if not new and modes.cycle_end is None:
                raise b.err(1, "X alone repeats a G92 pass: give G92 X Z F first")
            z_end = None if new or modes.cycle_end is None else modes.cycle_end[0]
            if new and "Z" not in v and "W" not in v:
                raise b.err(b.col("G"), "G92 gives the thread's end Z (or W)")
            end = _target(b, modes, here, z_end)
            if "R" in v:
                modes.cycle_taper = v["R"]
            elif new:
                modes.cycle_taper = 0.0
            modes.cycle_end = end
            modes.cycle_pass = 1 if new else modes.cycle_pass + 1
            segs = plan_g92(here, end, modes.cycle_taper, modes.lead, m, 0.0, modes.cycle_pass, b.line)
            ops.append(Thread(b.line, 92, tuple(segs), here))
            modes.motion = 92
            return here
        if modes.g76 is None:
            raise b.err(b.col("G"), "G76 X Z P Q F needs G76's first block (G76 P(m)(r)(a) Q(least depth) "
                                    "R(finishing allowance)) before it")
        if not any(k in v for k in "XU") or not any(k in v for k in "ZW"):
            raise b.err(b.col("G"), "G76's second block gives the thread's root X (or U) and its end Z (or W)")
        height, first = _microns(b, "P", "the thread height"), _microns(b, "Q", "the first depth of cut")
        end = _target(b, modes, here)
        segs = plan_g76(here, end, v.get("R", 0.0), height, first, modes.lead, modes.g76, m, 0.0, b.line)
        ops.append(Thread(b.line, 76, tuple(segs), here))
        return here
    except ThreadError as err:
        raise b.err(b.col(err.word), err.reason) from None


# -- single cycles: G90, G94 (:mod:`.single_cycles`) ---------------------------------------------------
def _single_kind(b: Block, modes: _Modes) -> int:
    """90 or 94 when the block is a single cycle's pass: G94; G90 with X/U or Z/W and no G00-G03 (G90 alone, or with
    a motion code, is RS274's absolute mode); or X/U or Z/W alone under a modal G90/G94 (not in a block with a
    one-shot code: G28 U0 W0 after the passes returns home)."""
    codes = [g for g, _ in b.g]
    moves = any(k in b.values for k in "XZUW")
    if 94 in codes:
        return 94
    if _ONE_SHOT.intersection(codes):
        return 0
    if any(g in _MOTION or g in _THREAD_MOTION or g == 76 for g in codes):
        return 0
    if 90 in codes and moves:
        return 90
    if modes.motion in (90, 94) and moves:
        return modes.motion or 0
    return 0


def _single(b: Block, kind: int, modes: _Modes, here: Point, ops: list[Op]) -> Point:
    """A G90/G94 pass from where the tool stands (the start point); it ends there again."""
    v = b.values
    modes.distance_and_x(b)
    for k in "IKPQ":
        if k in v:
            raise b.err(b.col(k), f"{k}: G{kind} takes X/U, Z/W, R (the taper) and F")
    if modes.comp:
        raise b.err(b.col("G"), f"G{kind} with G4{1 if modes.comp > 0 else 2} in force: cancel the tool-nose radius "
                                "compensation (G40) before a single cycle")
    new = kind in {g for g, _ in b.g} or modes.motion != kind
    if new and not (any(k in v for k in "XU") and any(k in v for k in "ZW")):
        raise b.err(b.col("G"), f"G{kind} gives the cut's end point: X (or U) and Z (or W)")
    previous = here if new or modes.cycle_end is None else modes.cycle_end
    end = _target(b, modes, here, previous[0])
    if not any(k in v for k in "XU"):
        end = (end[0], previous[1])
    if "R" in v:
        modes.cycle_taper = v["R"]                 # radius values (G90) or along Z (G94), as Fanuc
    elif new:
        modes.cycle_taper = 0.0
    if "F" in v:
        modes.feed = v["F"] / 60.0
    if modes.feed == 0.0:
        raise b.err(b.col("G"), f"G{kind} with no feed: give F first")
    low = min(end[1], end[1] + modes.cycle_taper) if kind == 90 else 0.0
    if low < -EPS:
        # a turning pass runs along Z at its X: below the axis the tool's far side is in the part (a G71 profile
        # crossing the axis is refused alike); a facing pass (G94) may end past the centre
        word = next((k for k in ("X", "U") if k in v), "R") if end[1] < -EPS else "R"
        given = f"{word}{v[word]:g}" if word in v else f"R{modes.cycle_taper:g} (modal)"
        raise b.err(b.col(word), f"{given}: G90's cut {'ends' if end[1] < -EPS else 'starts'} at X {low:g} "
                                 "(radius), across the spindle axis")
    modes.cycle_end = end
    modes.cycle_pass = 1 if new else modes.cycle_pass + 1
    try:
        segs = plan_single(kind, here, end, modes.cycle_taper, modes.feed, modes.cycle_pass, b.line)
    except CycleError as err:
        raise b.err(b.col(err.word), err.reason) from None
    ops.append(SingleCycle(b.line, kind, tuple(segs), here))
    modes.motion = kind
    return here


# -- peck cycles: G74, G75 (:mod:`.peck_cycles`) -------------------------------------------------------
_PECK = (74, 75)


def _peck_kind(b: Block) -> int:
    """74 or 75 when the block is a G74/G75's (non-modal: its own G code)."""
    return next((g for g, _ in b.g if g in _PECK), 0)


def _microns_word(b: Block, letter: str, what: str) -> float:
    """A peck cycle's P or Q: a whole number of um as Fanuc writes it, no decimal point (0 when absent), as mm."""
    spelled = next((text for w, _, text, _ in b.words if w == letter), None)
    if spelled is None:
        return 0.0
    value = b.values[letter]
    if "." in spelled or value != int(value) or value < 0:
        raise b.err(b.col(letter), f"{letter}{spelled}: {what} is a whole number of um >= 0 without a decimal point, "
                                   f"as Fanuc writes it ({letter}2500: 2.5 mm)")
    return value / 1000.0


def _no_such_tool(b: Block, row: int, what: str, tool: str, field: str) -> ProgramError:
    """The refusal of a cycle whose active offset's row (``row``; 0: no T yet) is not the ``tool`` it needs (its
    ``tool[k].<field>`` not set)."""
    if row:
        return b.err(b.col("G"), f"{what}: the active offset's row (tool[{row}]) is no {tool}: set "
                                 f"tool[{row}].{field}")
    return b.err(b.col("G"), f"{what}: give a {tool}'s offset first (T, its row's tool[k].{field})")


def _peck(b: Block, kind: int, modes: _Modes, here: Point, ops: list[Op]) -> Point:
    """A G74/G75 block: the first (R alone) sets the retract e; the second adds the cycle's :class:`.g7x.PeckCycle`
    from where the tool stands (the start point), where it ends again."""
    v = b.values
    modes.distance_and_x(b)
    pecks_along, steps_across = ("Z", "X") if kind == 74 else ("X", "Z")
    for k in "IK":
        if k in v:
            raise b.err(b.col(k), f"{k}: G{kind} takes R (the retract) in its first block, then X/U, Z/W, P, Q, R "
                                  "(the relief) and F")
    if modes.comp:
        raise b.err(b.col("G"), f"G{kind} with G4{1 if modes.comp > 0 else 2} in force: cancel the tool-nose radius "
                                "compensation (G40) before a peck cycle")
    if not any(k in v for k in "XZUWPQ"):
        if "R" not in v or "F" in v:
            raise b.err(b.col("F") if "F" in v else b.col("G"),
                        f"G{kind}'s first block gives the retract R (mm, after each peck) alone; the cut follows in "
                        f"G{kind} X/U Z/W P Q R F")
        if not v["R"] >= 0.0:
            raise b.err(b.col("R"), f"R{v['R']:g}: the retract after each peck must be >= 0")
        modes.peck_retract = v["R"]
        return here
    if modes.peck_retract is None:
        raise b.err(b.col("G"), f"G{kind} X Z P Q R F needs G{kind}'s first block (G{kind} R<retract, mm>) before "
                                "it")
    if not any(k in v for k in ("ZW" if kind == 74 else "XU")):
        raise b.err(b.col("G"), f"G{kind} gives the end {pecks_along} the pecks reach ({pecks_along} or "
                                f"{'W' if kind == 74 else 'U'})")
    p = _microns_word(b, "P", "the step in X" if kind == 74 else "the peck in X")
    q = _microns_word(b, "Q", "the peck in Z" if kind == 74 else "the step in Z")
    peck, step = (q, p) if kind == 74 else (p, q)
    end = _target(b, modes, here)
    if "F" in v:
        modes.feed = v["F"] / 60.0
    if modes.feed == 0.0:
        raise b.err(b.col("G"), f"G{kind} with no feed: give F first")
    tool, row = modes.row, modes.row_no
    across = b.col("X" if "X" in v else "U") if any(k in v for k in "XU") else b.col("P")
    if kind == 74 and (tool.drill_diameter > 0.0 or abs(here[1]) <= EPS):
        if tool.drill_diameter > 0.0 and abs(here[1]) > EPS:
            raise b.err(b.col("G"), f"G74 with a drill (tool[{row}].drill_diameter {tool.drill_diameter:g}) from X "
                                    f"{2 * here[1] if modes.diameter else here[1]:g}: a drill drills on the spindle "
                                    "axis, start G74 at X0")
        if abs(end[1] - here[1]) > EPS or step > 0.0:
            raise b.err(across, "G74 of a tool on the spindle axis steps across X: a drill makes one hole on the "
                                "axis (omit X/U and give P0)")
        if tool.drill_diameter <= 0.0:
            raise _no_such_tool(b, row, "G74 on the spindle axis drills", "drill", "drill_diameter")
        if end[0] > here[0]:
            raise b.err(b.col("Z" if "Z" in v else "W"), f"G74 to Z {end[0]:g} from Z {here[0]:g}: a drill drills "
                                                         "toward the chuck (-Z), its hole open toward the start point")
    if kind == 75:
        if tool.drill_diameter > 0.0:
            raise b.err(b.col("G"), f"G75 with a drill (tool[{row}].drill_diameter {tool.drill_diameter:g}): a drill "
                                    "cuts along Z on the axis, G75 grooves in X")
        if tool.width <= 0.0:
            raise _no_such_tool(b, row, "G75 grooves with a blade", "grooving blade", "width")
        inside = tool.tip in (1, 2)        # a bore's blade: its body below its edge (peck_cycles.region)
        if (end[1] > here[1] + EPS) != inside and abs(end[1] - here[1]) > EPS:
            raise b.err(b.col("X" if "X" in v else "U"),
                        f"G75 to X {2 * end[1] if modes.diameter else end[1]:g} from X "
                        f"{2 * here[1] if modes.diameter else here[1]:g}: tool[{row}].tip {tool.tip} is an "
                        f"{'inside' if inside else 'outside'} blade: its pecks run "
                        f"{'away from' if inside else 'toward'} the axis")
        if step > tool.width + EPS:
            raise b.err(b.col("Q"), f"Q{round(step * 1000)}: steps of {step:g} mm in Z wider than the blade "
                                    f"(tool[{row}].width {tool.width:g}) leave a ridge between the plunges")
    try:
        segs = plan_pecks(kind, here, end, peck, step, modes.peck_retract, v.get("R", 0.0), modes.feed, b.line)
    except PeckError as err:
        word = err.word if err.word in v else {"X": "U", "Z": "W"}.get(err.word, err.word)
        raise b.err(across if err.word == steps_across and word not in v else b.col(word), err.reason) from None
    ops.append(PeckCycle(b.line, kind, tuple(segs), here, region(kind, here, end, tool)))
    return here


# -- direct drawing dimensions: ,C ,R A (:mod:`.direct_dimensions`) ---------------------------------------
_DIMENSION_WORDS = (",C", ",R", "A")


def _corner_word(b: Block) -> str:
    """",C" or ",R" when the block chamfers or rounds its corner with the next move, else ""."""
    found = [k for k in (",C", ",R") if k in b.values]
    if len(found) > 1:
        raise b.err(b.col(found[1]), ",C and ,R in one block: a corner is chamfered or rounded, not both")
    return found[0] if found else ""


def _no_dimensions(b: Block, what: str) -> None:
    for k in _DIMENSION_WORDS:
        if k in b.values:
            raise b.err(b.col(k), f"{k}{b.values[k]:g} in {what}: ,C, ,R and A belong to G01 moves")


def _check_corner_move(b: Block, word: str, element: Element | None, rapid: bool) -> None:
    """The block that chamfers or rounds (``word``) is itself a G01 move."""
    if word and (element is None or rapid or not isinstance(element, Line)):
        what = "an arc" if isinstance(element, Arc) else "a rapid (G00)" if rapid and element else "no move"
        raise b.err(b.col(word), f"{word}{b.values[word]:g} on {what}: {word} stands between two G01 moves")


def _move_at(ops: list[Op], k: int) -> Move:
    m = ops[k]
    assert isinstance(m, Move)
    return m


def _round_corner(pb: Block, word: str, prev: Move, b: Block, element: Element | None,
                  rapid: bool) -> tuple[Move | None, Move, Element | None]:
    """The corner of ``pb`` (``word``) between its move ``prev`` and the next block ``b``'s ``element``: the first
    move shortened (None: nothing left), the chamfer or arc (a move of ``pb``), the next element shortened."""
    if element is None or rapid or not isinstance(element, Line) or not isinstance(prev.element, Line):
        what = ("an arc" if isinstance(element, Arc) else "a rapid (G00)" if rapid and element else
                "no move (the move must follow directly)")
        raise pb.err(pb.col(word), f"{word}{pb.values[word]:g}: the next block (line {b.line}) is {what}: {word} "
                                   "stands between two G01 moves")
    try:
        before, middle, after = corner(prev.element, element, word, pb.values[word])
    except DimensionError as err:
        raise pb.err(pb.col(err.word), err.reason) from None
    return (replace(prev, element=before) if before is not None else None), replace(prev, element=middle), after


# -- the program ------------------------------------------------------------------------------------
def _whole(b: Block, values: dict[str, float], letter: str, code: int) -> int:
    if letter not in values:
        raise b.err(1, f"G{code} P Q: {letter} (the {'first' if letter == 'P' else 'last'} block number of the "
                       "profile) is missing")
    v = values[letter]
    if v != int(v) or v < 0:
        raise b.err(b.col(letter), f"{letter}{v:g}: a block number is a whole number >= 0")
    return int(v)


def _read_profile(blocks: list[Block], i: int, b: Block, p: int, q: int, modes: _Modes,
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
    front: Element | None = None
    pieces: list[Move] = []
    pending: tuple[Block, str] | None = None    # the block whose ,C or ,R waits for the next move
    j = i
    while True:
        blk = blocks[j]
        if blk.ends:
            raise blk.err(blk.col("M"), f"the program ends inside the profile N{p}..N{q}")
        machine = [k for k in "MST" if k in blk.values or (k == "M" and blk.m)]
        machine += [f"G{g:02d}" for g, _ in blk.g if g in _NOT_IN_PROFILE]
        if machine:
            raise blk.err(blk.col(machine[0][0]), f"{machine[0]} inside the profile N{p}..N{q}: the profile is the "
                                                  "part's outline (moves, F), give it before G71/G70")
        element, end, rapid, cycle = _interpret(blk, modes, here, profile=True)
        if cycle is not None:
            raise blk.err(blk.col("G"), f"G{cycle.code} inside the profile N{p}..N{q}")
        word = _corner_word(blk)
        _check_corner_move(blk, word, element, rapid)
        if pending is not None:
            first, middle, element = _round_corner(pending[0], pending[1], pieces[-1], blk, element, rapid)
            pieces[-1:] = [first, middle] if first is not None else [middle]
            pending = None
        if word:
            if j == i:
                raise blk.err(blk.col(word), f"{word} on the profile's first block N{p} (the move from the start "
                                             "point): give it on the profile's own moves")
            if element is None:
                raise blk.err(blk.col(word), f"{word}: the corner before takes this whole move")
            pending = (blk, word)
        if j == i and code in (72, 73):
            reason = first_block_error(code, element, start, end)
            if reason:
                raise blk.err(1, reason)
            assert element is not None
            lead = Move(element, rapid, modes.feed, blk.line, raw=blk.raw.strip())
        elif j == i:
            if element is None or isinstance(element, Arc) or end[0] > start[0] + EPS:
                raise blk.err(1, f"the profile's first block N{p} moves in a straight line from the start point "
                                 f"(X {start[1]:g}, Z {start[0]:g}) to the profile's start, in X (type I) or in X "
                                 "and Z (type II), not in front of the start point's Z (Fanuc's form)")
            lead = Move(element, rapid, modes.feed, blk.line, raw=blk.raw.strip())
            if end[0] < start[0] - EPS:          # the profile in front of its start: at its X from S's Z on
                front = Line((start[0], end[1]), end)
        elif element is not None:
            pieces.append(Move(element, rapid, modes.feed, blk.line, raw=blk.raw.strip()))
        here = end
        j += 1
        if blk.n == q:
            if pending is not None:
                raise blk.err(blk.col(pending[1]), f"{pending[1]} on the profile's last block N{q}: no move after it "
                                                   "in the profile")
            break
    modes.motion, modes.incremental, modes.diameter, modes.feed = (saved.motion, saved.incremental,
                                                                   saved.diameter, saved.feed)
    if not pieces:
        raise b.err(b.col("Q"), f"the profile N{p}..N{q} has no block after its first (the outline of the part)")
    profile = Profile(p, q, lead, tuple(pieces), front=front)
    if code in (72, 73):
        check_face_or_pattern(code, profile, start)
        return profile, j
    if lead.element.end[1] > start[1] + TOL:     # X rises to the profile: a bore, checked as the outside it mirrors
        pocket = check_profile(mirror_profile(profile, start[1]), start, inside=True)
        return replace(profile, pocket=pocket, inside=True), j
    return replace(profile, pocket=check_profile(profile, start)), j


def _face_or_pattern(b: Block, first: FirstBlock | None, here: Point, profile: Profile, modes: _Modes,
                     feed: float) -> Op:
    """G72 P Q U W F or G73 P Q U W F (:mod:`.g72_g73`) after its first block ``first``."""
    code = 72 if any(g == 72 for g, _ in b.g) else 73
    if first is None:
        raise b.err(1, f"G{code} P Q needs G{code}'s first block (" + ("G72 W<depth> R<retract>" if code == 72 else
                                                                       "G73 U<escape X> W<escape Z> R<passes>")
                       + ") before it")
    if modes.comp:
        raise b.err(b.col("G"), f"G{code} with G4{1 if modes.comp > 0 else 2} in force: G{code} roughs "
                                "uncompensated, cancel the tool-nose radius compensation (G40) first")
    feed = feed or modes.feed
    if feed == 0.0:
        raise b.err(1, f"G{code} with no feed: give F (mm/min) here or before")
    u = b.values.get("U", 0.0) * (0.5 if modes.diameter else 1.0)
    w = b.values.get("W", 0.0)
    make = face_rough if code == 72 else pattern_repeat
    return make(b, first, here, profile, u, w, feed)


def parse(text: str, start: tuple[float, float], setup: Setup | None = None) -> list[Op]:
    """The operations of a lathe program read with ``setup`` (default :class:`Setup`: X a diameter, feed per
    minute, eight tools without offsets, no G28); the tool starts at ``start`` = (x, z).

    Raises
    ------
    ProgramError
        naming the line, the column and the reason: every reading error at once (:func:`.gcode.read`), else
        the first error of conversion.
    """
    setup = setup or Setup()
    blocks = run_order(read(text, LATHE, setup.block_delete))
    if len(setup.works) != len(_WORK):
        raise ValueError(f"Setup.works: {len(setup.works)} work offsets, G54..G59 take {len(_WORK)}")
    work = setup.works[0]                                   # G54 at power-on
    modes = _Modes(diameter=setup.diameter, machine=Modal(per_rev=setup.feed_per_rev, offset=work), work=work)
    here: Point = (start[1] - work[0], start[0] - work[1])  # the programmed point where the tool stands
    ops: list[Op] = [State(blocks[0].line, modes.machine, power_on=True)] if modes.machine != NO_MODAL else []
    profiles: dict[tuple[int, int], Profile] = {}
    noses: dict[int, Nose] = {}             # index of a move under G41/G42 in ops -> its nose
    g71_first: tuple[float, float] | None = None
    firsts: dict[int, FirstBlock] = {}      # G72's and G73's first blocks
    kinds: dict[tuple[int, int], int] = {}  # the cycle (70-73) that read each profile
    pending: tuple[int, Block, str] | None = None   # the move (its index in ops) whose ,C or ,R waits for the next
    i = 0
    while i < len(blocks):
        b = blocks[i]
        i += 1
        peck = _peck_kind(b)
        single = 0 if peck else _single_kind(b, modes)
        thread = 0 if single or peck else _thread_kind(b, modes)
        if single or peck:
            _check_thread_words(b, single or peck, spindle=False)
        if thread:
            _check_thread_words(b, thread)
        before = modes.machine
        _machine(b, modes, setup)
        if modes.machine != before:
            ops.append(State(b.line, modes.machine))
        codes = {g for g, _ in b.g}
        cycle = None
        if single or thread or peck or codes & {4, 28, 50}:
            _no_dimensions(b, f"a G{single or thread or peck or min(codes & {4, 28, 50}):02d} block")
            if pending is not None:
                _round_corner(pending[1], pending[2], _move_at(ops, pending[0]), b, None, False)   # raises: no G01 next
        if codes & {4, 28, 50}:
            for g, col in b.g:
                if g not in (4, 28, 50, 40):
                    raise b.err(col, f"G{g:02d} in a G04/G28/G50 block: give it a block of its own")
            if 40 in codes:
                modes.comp = 0
            if 28 in codes and modes.comp:
                raise b.err(b.col("G"), f"G28 with G4{1 if modes.comp > 0 else 2} in force: cancel the tool-nose "
                                        "radius compensation (G40) on the way out first")
            if 4 in codes:
                ops.append(_dwell(b))
            elif 28 in codes:
                home = _home(b, modes, here, setup)
                ops.append(home)
                dz, dx = modes.machine.offset           # the reference is the axes': the programmed point is off
                here = (home.home[0] - dz if home.home[0] is not None else home.via[0],
                        home.home[1] - dx if home.home[1] is not None else home.via[1])
        elif single:
            here = _single(b, single, modes, here, ops)
        elif peck:
            here = _peck(b, peck, modes, here, ops)
        elif thread:
            here = _thread(b, thread, modes, here, ops)
        else:
            comp_before = modes.comp
            element, end, rapid, cycle = _interpret(b, modes, here)
            word = _corner_word(b)
            _check_corner_move(b, word, element, rapid)
            if pending is not None:
                at, corner_block, corner_word = pending
                first, middle, element = _round_corner(corner_block, corner_word, _move_at(ops, at), b, element,
                                                       rapid)
                if first is None:
                    ops[at] = middle
                else:
                    ops[at] = first
                    ops.append(middle)
                    if at in noses:
                        noses[len(ops) - 1] = noses[at]
                pending = None
            if element is not None:
                ops.append(Move(element, rapid, modes.feed, b.line, comp_before, modes.comp, raw=b.raw.strip()))
                if modes.comp:
                    noses[len(ops) - 1] = Nose(modes.comp, modes.row.nose_radius, modes.row.tip)
            if word:
                if element is None:
                    raise b.err(b.col(word), f"{word}: the corner before takes this whole move")
                pending = (len(ops) - 1, b, word)
            here = end
        after = _after_move(b, modes)
        if after is not None:
            ops.append(after)
        if cycle is None:
            continue
        v = cycle.values
        if cycle.code in (72, 73) and "P" not in v and "Q" not in v:
            firsts[cycle.code] = first_block(b)
            continue
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
            first_words = {71: "the retract belongs to G71's first block (G71 U R)",
                           72: "the retract belongs to G72's first block (G72 W R)",
                           73: "the number of passes belongs to G73's first block (G73 U W R)"}
            raise b.err(b.col("R"), f"R: {first_words[cycle.code]}")
        feed = v["F"] / 60.0 if "F" in v else 0.0
        if i < len(blocks) and blocks[i].n == p:
            profile, i = _read_profile(blocks, i, b, p, q, modes, here, cycle.code)
            profiles[(p, q)] = profile
            kinds[(p, q)] = cycle.code
        elif (p, q) in profiles:
            profile = profiles[(p, q)]
            (z1, x1) = profile.lead.element.start
            read_by = kinds[(p, q)] if kinds[(p, q)] != 70 else 71
            if cycle.code != 70 and read_by != cycle.code:
                raise b.err(b.col("P"), f"P{p}: the profile N{p}..N{q} was read as G{read_by}'s: G{cycle.code} "
                                        "takes a profile of its own (its rules differ)")
            if cycle.code != 70 and math.dist((z1, x1), here) > EPS:
                raise b.err(b.col("P"), f"P{p}: the profile N{p}..N{q} was read from the start point X {x1:g} Z "
                                        f"{z1:g}, this G{cycle.code} starts at X {here[1]:g} Z {here[0]:g}")
        else:
            profile, _ = _read_profile(blocks, i, b, p, q, modes, here, cycle.code)   # raises: not found
        if cycle.code == 70:
            if feed == 0.0:
                for pb in (profile.lead, *profile.blocks):
                    if not pb.rapid and pb.feed == 0.0:
                        raise b.err(1, f"G70: the profile's block on line {pb.line} has no feed: give F")
            if kinds[(p, q)] == 72:
                ops.append(face_finish(b, here, profile, feed, modes.comp))
                continue
            nose = Nose(modes.comp, modes.row.nose_radius, modes.row.tip) if modes.comp else None
            finish = Finish(b.line, here, profile, feed, nose)
            if nose is not None:
                if nose.side > 0 and not profile.inside:
                    raise b.err(b.col("G"), "G70 with G41 on an outside profile puts the nose on the part's side "
                                            "(below the profile): turning toward the chuck takes G42")
                if nose.side < 0 and profile.inside:
                    raise b.err(b.col("G"), "G70 with G42 on an inside profile puts the nose on the part's side "
                                            "(above the bore's profile): boring toward the chuck takes G41")
                finish_path(finish)                  # raises where the nose cannot follow the profile
            ops.append(finish)
            continue
        if cycle.code in (72, 73):
            ops.append(_face_or_pattern(b, firsts.get(cycle.code), here, profile, modes, feed))
            continue
        if g71_first is None:
            raise b.err(1, "G71 P Q needs G71's first block (G71 U<depth> R<retract>) before it")
        u = v.get("U", 0.0) * (0.5 if modes.diameter else 1.0)
        w = v.get("W", 0.0)
        if profile.inside and u > 0:
            raise b.err(b.col("U"), f"U{v['U']:g}: an inside profile (boring: X rises from the start point's X "
                                    f"{here[1]:g}) takes U <= 0, the allowance toward the axis (Fanuc's U-0.4): a "
                                    "positive one would cut into the part")
        if (u < 0 and not profile.inside) or w < 0:
            k = "U" if u < 0 else "W"
            raise b.err(b.col(k), f"{k}{v[k]:g}: a negative allowance would cut into the part (on an outside "
                                  "profile; a negative U is a bore's, whose profile rises from the start point)")
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
        outside = mirror_op(rough) if profile.inside else rough          # an inside one as the outside it mirrors
        low = min(min(e.start[1], e.end[1]) for e in monotone_pieces(rough_boundary(outside)))  # type: ignore[arg-type]
        if low >= here[1] - TOL:
            low, where = (2 * here[1] - low, "above") if profile.inside else (low, "below")
            raise b.err(b.col("U"), f"U{v.get('U', 0.0):g}: the profile shifted by the allowance lies nowhere {where} "
                                    f"the start point's X {here[1]:g} (its {'highest' if profile.inside else 'lowest'}"
                                    f" X {low:g}): nothing to rough, and G70 would take the whole depth in one pass")
        ops.append(rough)
    if pending is not None:
        _round_corner(pending[1], pending[2], _move_at(ops, pending[0]), blocks[-1], None, False)   # raises
    if not ops:
        raise ProgramError(blocks[-1].line, 1, blocks[-1].raw.strip(), "the program has no moves")
    return _compensate(ops, noses) if noses else ops


def _compensate(ops: list[Op], noses: dict[int, Nose]) -> list[Op]:
    """The moves under G41/G42 (``noses``: index of the move -> its nose) as the tool's imaginary tip commands them.

    A run of compensated moves (the machine's state, dwells and stops may stand between them) is as the mill's
    (:func:`.contour.program_path`): the start-up move (the first), the profile (the moves after it), and the
    cancel move -- the first move after with G40, or, when the run ends at a G70/G71, its last move (to the
    cycle's start point, which is programmed uncompensated). Type A: the start-up ends with the nose centre
    normal to the next move's start, the cancel starts normal to the previous move's end; a run of one or two
    moves has no profile and is not offset. A run at the program's end has no cancel: its last move is offset.
    """
    out: list[Op] = []
    i = 0
    while i < len(ops):
        if i not in noses:
            out.append(ops[i])
            i += 1
            continue
        nose = noses[i]
        run, j = [], i
        while j < len(ops) and (j in noses or isinstance(ops[j], (State, Dwell, Stop))):
            if j in noses:
                run.append(j)
            j += 1
        after = ops[j] if j < len(ops) else None
        cancel = (j if isinstance(after, Move) else
                  run.pop() if isinstance(after, (Rough, Finish)) and len(run) > 1 else None)
        first = ops[run[0]]
        assert isinstance(first, Move)
        for k in (run[0], cancel):
            m = ops[k] if k is not None else None
            if isinstance(m, Move) and isinstance(m.element, Arc):
                what = ("start-up (the first move after G41/G42)" if k == run[0] else
                        "cancel (the G40 move, or the move to a canned cycle's start point)")
                raise ProgramError(m.line, 1, m.raw, f"G02/G03 as the tool-nose radius compensation's {what}: give a "
                                                     "straight move (G00/G01) there")
        for k in run:
            m = ops[k]
            assert isinstance(m, Move)
            if noses[k] != nose:
                raise ProgramError(m.line, 1, m.raw, f"{noses[k].code} while {nose.code} is in force: change sides "
                                                     "through G40 (cancel, then start up again)")
        chain = [m for k in run[1:] if isinstance(m := ops[k], Move)]
        new: dict[int, list[Move]] = {}
        if chain:
            try:
                pieces = nose.path([m.element for m in chain])
            except CornerError as err:
                bad = chain[err.index]
                reason = err.describe([f"the block on line {m.line}" for m in chain])
                raise ProgramError(bad.line, 1, bad.raw, f"tool-nose radius compensation ({nose.code}, nose radius "
                                                         f"{nose.radius:g} mm): {reason}") from None
            entry, exit_ = pieces[0][0].start, pieces[-1][0].end
            for e, k in pieces:
                m = chain[k]
                new.setdefault(run[k + 1], []).append(replace(m, element=e))
        else:
            entry = exit_ = first.element.end
        new[run[0]] = [replace(first, element=Line(first.element.start, entry))]
        if cancel is not None:
            m = ops[cancel]
            assert isinstance(m, Move)
            new[cancel] = [replace(m, element=Line(exit_, m.element.end))]
        last = cancel if cancel is not None and cancel >= j else j - 1
        for k in range(i, last + 1):
            if k in new:
                out += [m for m in new[k] if m.element.length > EPS]
            else:
                out.append(ops[k])
        i = last + 1
    return out


def work_offsets(value: Callable[[str], float]) -> tuple[Point, ...]:
    """Setup.works from the sequencer's parameters ``seq.work[k].x`` / ``.z``, ``value(name)`` giving each."""
    return tuple((value(f"work[{k}].z"), value(f"work[{k}].x")) for k in range(1, len(_WORK) + 1))


def has_block_delete(text: str) -> bool:
    """Whether a block of the program starts with '/' (the block-delete switch matters)."""
    return any(strip_comments(line, n).lstrip().startswith("/") for n, line in enumerate(program_lines(text), 1))


def plan(text: str, start: tuple[float, float], rapid: float, setup: Setup | None = None) -> list[Segment]:
    """Every move of a program read with ``setup`` (the tool at ``start`` = (x, z)), G00 and the cycles' rapids at
    ``rapid`` mm/s."""
    return plan_ops(parse(text, start, setup), rapid, (start[1], start[0]))
