"""Part programs in an RS274/NGC subset (the form LinuxCNC and Fanuc users write), XY plane, mm.

Words (one block per line, letters in either case, spaces allowed between a letter and its number)::

    G00 rapid   G01 line   G02 clockwise arc   G03 counter-clockwise arc   (motion, modal)
    G17 XY plane   G21 mm   G90 absolute   G91 incremental                 (modal)
    G40 compensation off   G41 left of travel   G42 right of travel        (modal)
    X Y end point   I J arc centre relative to the arc's start (always incremental)
    F feed in mm/min (modal)   N block number (ignored)   O program number (ignored)   M02 / M30 program end
    ( comment )   ; comment to the end of the line   a line holding only % is skipped

Cutter compensation as LinuxCNC and Fanuc: G41/G42 takes effect with the next move, a straight lead-in
to the offset start of the contour; G40 ends it with a straight lead-out from the offset end. The
offset is ``diameter_delta / 2``. Everything else -- other G/M codes, Z, R-format arcs, parameters,
expressions -- is refused with the line, the column and the reason (every reading error of a program at once,
:mod:`.gcode`); nothing is evaluated. This module is the mill's dialect (a table) and its conversion: the
moves in the XY plane and the compensation state around them; reading and checking are :mod:`.gcode`'s.
"""

from __future__ import annotations

import math

from ..errors import ProgramError
from .gcode import (  # noqa: F401  (the front end's limits, named here as the mill's)
    ARC_RADIUS_TOLERANCE,
    COMP_SIDE,
    COORDINATE_LIMIT,
    MAX_PROGRAM_CHARS,
    POINT_EPS,
    Dialect,
    Modes,
    Move,
    arc,
    read,
)
from .geometry import Element, Line, Point

#: More moves than this are refused: the gouge check measures the offset path against the whole contour.
MAX_MOVES = 2000

_MOTION = {0, 1, 2, 3}
MILL = Dialect(
    name="mill",
    groups={**{g: "motion (G00-G03)" for g in _MOTION}, 17: "plane (G17)", 21: "units (G21)",
            90: "distance mode (G90/G91)", 91: "distance mode (G90/G91)",
            40: "cutter compensation (G40-G42)", 41: "cutter compensation (G40-G42)",
            42: "cutter compensation (G40-G42)"},
    refused_g={18: "only the XY plane (G17) is in the subset", 19: "only the XY plane (G17) is in the subset",
               20: "inch units are not in the subset: write the program in mm (G21)",
               43: "tool length offsets are not in the subset"},
    g_list="G00-G03, G17, G21, G40-G42, G90, G91",
    m_codes=frozenset({2, 30}), m_list="M02, M30",
    coordinates="XYIJO",            # O: the program number, read and ignored (as the lathe's, lathe_program.py)
    refused_letters={"R": "R-format arcs are not in the subset: give the centre with I and J",
                     "Z": "only the XY plane is in the subset (no Z)",
                     "D": "the offset is diameter_delta / 2, not a D word"},
    letter_list="G, M, N, O, X, Y, I, J, F",
    axes=(("X", ""), ("Y", "")),
)


def parse(text: str, start: Point) -> list[Move]:
    """The moves of a program that starts with the tool at ``start``.

    Raises
    ------
    ProgramError
        naming the line, the column and the reason: every reading error at once (:func:`.gcode.read`), else
        the first error of conversion.
    """
    blocks = read(text, MILL)
    moves: list[Move] = []
    modes = Modes()
    comp_moved = 0                # compensation in force after the last move
    here = start
    for b in blocks:
        n, raw, values = b.line, b.raw, b.values
        new_motion = None
        motion_col = None
        modes.distance_and_x(b)
        for g, col in b.g:
            if g in _MOTION:
                new_motion, motion_col = g, col
            elif g in COMP_SIDE:
                side = COMP_SIDE[g]
                if side and (modes.comp or comp_moved):
                    on = modes.comp or comp_moved
                    raise b.err(col, f"G{g}: cutter compensation is already on (G{41 if on > 0 else 42}); turn it "
                                     "off with G40 and a lead-out move first")
                modes.comp = side
        modes.feed_word(b)
        if new_motion is not None:
            modes.motion = new_motion
        motion = modes.motion
        has_xy = "X" in values or "Y" in values
        has_ij = "I" in values or "J" in values
        xy_col = min((b.col(k) for k in "XY" if k in values), default=1)
        ij_col = min((b.col(k) for k in "IJ" if k in values), default=1)
        move_col = motion_col or xy_col                       # the motion word, or the first coordinate
        if has_ij and motion not in (2, 3):
            raise b.err(ij_col, "I and J belong to G02/G03 arcs")
        if has_xy or has_ij:
            if motion is None:
                raise b.err(xy_col, "a move with no motion mode: give G00, G01, G02 or G03 first")
            if motion != 0 and modes.feed == 0.0:
                raise b.err(move_col, f"G{motion:02d} with no feed: give F (mm/min) first")
            x, y = here
            tx, ty = modes.end(b, here, MILL.axes)
            if max(abs(tx), abs(ty)) > COORDINATE_LIMIT:
                raise b.err(xy_col, f"the move ends at ({tx:g}, {ty:g}): beyond {COORDINATE_LIMIT:g} mm, no machine "
                                    "is that large")
            element: Element | None = None
            if motion in (2, 3):
                if not has_ij:
                    raise b.err(move_col, f"G{motion:02d} needs the centre as I and/or J (R-format arcs are not in "
                                          "the subset)")
                centre = (x + values.get("I", 0.0), y + values.get("J", 0.0))
                element, (tx, ty) = arc(b, (x, y), (tx, ty), centre, motion == 3, ij_col, "I/J")
            elif math.hypot(tx - x, ty - y) > POINT_EPS:
                element = Line((x, y), (tx, ty))
            if element is not None:
                if modes.comp != comp_moved and not isinstance(element, Line):
                    what = "start" if modes.comp else "end"
                    raise b.err(move_col, f"an arc cannot {what} cutter compensation: program a straight "
                                          f"{'lead-in' if modes.comp else 'lead-out'} move (G00/G01)")
                if len(moves) == MAX_MOVES:
                    raise b.err(move_col, f"more than {MAX_MOVES} moves: split the program")
                moves.append(Move(element, motion == 0, modes.feed, n, comp_moved, modes.comp, raw.strip()))
                comp_moved = modes.comp
                here = (tx, ty)
        if b.ends:
            if comp_moved or modes.comp:
                raise b.err(b.col("M"), "cutter compensation is still on at the program end: end it with G40 and a "
                                        "lead-out move")
    if not moves:
        last = blocks[-1]
        raise ProgramError(last.line, 1, last.raw.strip(), "the program has no moves")
    return moves
