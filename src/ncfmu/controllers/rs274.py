"""Part programs in an RS274/NGC subset (the form LinuxCNC and Fanuc users write), XY plane, mm.

Words (one block per line, letters in either case, spaces allowed between a letter and its number)::

    G00 rapid   G01 line   G02 clockwise arc   G03 counter-clockwise arc   (motion, modal)
    G17 XY plane   G21 mm   G90 absolute   G91 incremental                 (modal)
    G40 compensation off   G41 left of travel   G42 right of travel        (modal)
    X Y end point   I J arc centre relative to the arc's start (always incremental)
    F feed in mm/min (modal)   N block number (ignored)   M02 / M30 program end
    ( comment )   ; comment to the end of the line   a line holding only % is skipped

Cutter compensation as LinuxCNC and Fanuc: G41/G42 takes effect with the next move, a straight lead-in
to the offset start of the contour; G40 ends it with a straight lead-out from the offset end. The
offset is ``diameter_delta / 2``. Everything else -- other G/M codes, Z, R-format arcs, parameters,
expressions -- is refused with the line, the column and the reason; nothing is evaluated.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from ..errors import ProgramError
from .geometry import Arc, Element, Line, Point, arc_through

#: Programs longer than this are refused (characters): a part program for one contour is far shorter.
MAX_PROGRAM_CHARS = 200_000
#: More moves than this are refused: the gouge check measures the offset path against the whole contour.
MAX_MOVES = 2000
#: Points closer than this are one point (mm): a move shorter is no move (rounding of G91 sums).
POINT_EPS = 1e-9
#: Radii from the centre to the start and to the end of an arc may differ by this much (mm), as
#: LinuxCNC's arc check. The centre moves onto the chord's bisector when that is at most this far, so the
#: arc runs through both points; else (short chords) it keeps its centre and radius and ends on its circle
#: toward the programmed end point, at most this far from it, and the next block starts there.
ARC_RADIUS_TOLERANCE = 0.002
#: A coordinate beyond this is refused (mm): no machine axis is that long.
COORDINATE_LIMIT = 1.0e5

_MOTION = {0, 1, 2, 3}
_GROUPS = {**{g: "motion (G00-G03)" for g in _MOTION}, 17: "plane (G17)", 21: "units (G21)",
           90: "distance mode (G90/G91)", 91: "distance mode (G90/G91)",
           40: "cutter compensation (G40-G42)", 41: "cutter compensation (G40-G42)",
           42: "cutter compensation (G40-G42)"}
_REFUSED_G = {18: "only the XY plane (G17) is in the subset", 19: "only the XY plane (G17) is in the subset",
              20: "inch units are not in the subset: write the program in mm (G21)",
              43: "tool length offsets are not in the subset"}
_WORD = re.compile(r"([A-Za-z])[ \t]*([+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+))?")


@dataclass(frozen=True)
class Move:
    """One programmed move: its geometry and how it is run."""

    element: Element
    rapid: bool             # G00: at the rapid rate, not the programmed feed
    feed: float             # programmed feed, mm/s (for G00: the last F, unused)
    line: int               # program line (1-based)
    comp_before: int        # cutter compensation in force before the move: 0 off, +1 left, -1 right
    comp_after: int         # ... and after it (a change is a lead-in or a lead-out)


def strip_comments(text: str, line_no: int) -> str:
    """The line with comments blanked out (columns kept)."""
    out, depth_at = [], None
    for col, ch in enumerate(text, start=1):
        if depth_at is not None:
            out.append(" ")
            if ch == ")":
                depth_at = None
            elif ch == "(":
                raise ProgramError(line_no, col, text.strip(), "'(' inside a comment: comments do not nest")
            continue
        if ch == "(":
            depth_at = col
            out.append(" ")
        elif ch == ";":
            out.append(" " * (len(text) - col + 1))
            break
        else:
            out.append(ch)
    if depth_at is not None:
        raise ProgramError(line_no, depth_at, text.strip(), "comment not closed with ')'")
    return "".join(out)


def words(text: str, line_no: int) -> list[tuple[str, float, str, int]]:
    """(letter, value, spelled number, column) of every word of a comment-free line."""
    found, col = [], 0
    while col < len(text):
        if text[col].isspace():
            col += 1
            continue
        m = _WORD.match(text, col)
        if not m or not m.group(1):
            ch = text[col]
            reason = ("parameters and expressions are not in the subset" if ch in "#[]=" else
                      "block delete '/' is not in the subset" if ch == "/" else f"unexpected character {ch!r}")
            raise ProgramError(line_no, col + 1, text.strip(), reason)
        letter = m.group(1).upper()
        if m.group(2) is None:
            nxt = text[m.end(1):].lstrip()[:1]
            reason = ("parameters and expressions are not in the subset" if nxt in ("#", "[") else
                      f"word {letter} needs a number")
            raise ProgramError(line_no, col + 1, text.strip(), reason)
        value = float(m.group(2))
        if not math.isfinite(value) or abs(value) > 1e15:
            raise ProgramError(line_no, col + 1, text.strip(), f"{letter}{m.group(2)[:20]}...: number too large")
        found.append((letter, value, m.group(2), col + 1))
        col = m.end()
    return found


def program_lines(text: str) -> list[str]:
    """A program's lines, after its length check: only newlines end a line (str.splitlines would also split at
    form feeds, U+2028 ...), a trailing CR is dropped. The mill's and the lathe's parsers read programs so."""
    if len(text) > MAX_PROGRAM_CHARS:
        raise ProgramError(1, 1, f"<{len(text)} characters>", f"longer than {MAX_PROGRAM_CHARS} characters")
    return [line[:-1] if line.endswith("\r") else line for line in text.split("\n")]


def check_once(seen: dict[str, int], i: int, letter: str, col: int, n: int, raw: str) -> None:
    """Word ``i`` of a block, at column ``col``: each letter but G at most once a block (``seen``: letter ->
    first column), and N only as the first word."""
    if letter in seen and letter != "G":
        raise ProgramError(n, col, raw.strip(), f"{letter} given twice in one block (first at column {seen[letter]})")
    seen.setdefault(letter, col)
    if letter == "N" and i != 0:
        raise ProgramError(n, col, raw.strip(), "the block number N must be the first word")


def parse(text: str, start: Point) -> list[Move]:
    """The moves of a program that starts with the tool at ``start``.

    Raises
    ------
    ProgramError
        naming the line, the column and the reason, for the first thing outside the subset or wrong.
    """
    lines = program_lines(text)
    moves: list[Move] = []
    motion: int | None = None
    incremental = False
    feed = 0.0                    # mm/s; 0 until an F word
    comp = 0                      # modal state
    comp_moved = 0                # compensation in force after the last move
    x, y = start
    ended_at = 0
    for n, raw in enumerate(lines, start=1):
        if ended_at:
            rest = strip_comments(raw, n) if raw.strip() != "%" else ""
            if rest.strip():
                raise ProgramError(n, len(rest) - len(rest.lstrip()) + 1, raw.strip(),
                                   f"text after the program end (line {ended_at})")
            continue
        if raw.strip() == "%":
            continue
        block = words(strip_comments(raw, n), n)
        if not block:
            continue
        seen: dict[str, int] = {}
        groups: dict[str, int] = {}
        values: dict[str, float] = {}
        new_motion = None
        motion_col = None
        end_program = False
        for i, (letter, value, spelled, col) in enumerate(block):
            here = f"{letter}{spelled}"
            check_once(seen, i, letter, col, n, raw)
            if letter == "N":
                continue
            if letter == "G":
                if value != int(value) or value > 99:
                    raise ProgramError(n, col, raw.strip(), f"{here} is not in the subset")
                g = int(value)
                if g in _REFUSED_G:
                    raise ProgramError(n, col, raw.strip(), f"{here}: {_REFUSED_G[g]}")
                if g not in _GROUPS:
                    raise ProgramError(n, col, raw.strip(), f"{here} is not in the subset (G00-G03, G17, G21, "
                                                            "G40-G42, G90, G91)")
                group = _GROUPS[g]
                if group in groups:
                    raise ProgramError(n, col, raw.strip(), f"G{groups[group]:02d} and {here} in one block: both "
                                                            f"belong to the modal group {group}")
                groups[group] = g
                if g in _MOTION:
                    new_motion, motion_col = g, col
                elif g in (90, 91):
                    incremental = g == 91
                elif g in (40, 41, 42):
                    side = {40: 0, 41: 1, 42: -1}[g]
                    if side and (comp or comp_moved):
                        on = comp or comp_moved
                        raise ProgramError(n, col, raw.strip(), f"{here}: cutter compensation is already on "
                                                                f"(G{41 if on > 0 else 42}); turn it off with "
                                                                "G40 and a lead-out move first")
                    comp = side
                continue
            if letter == "M":
                if value not in (2, 30):
                    raise ProgramError(n, col, raw.strip(), f"{here} is not in the subset (M02, M30)")
                end_program = True
                continue
            if letter == "F":
                if not value > 0:
                    raise ProgramError(n, col, raw.strip(), f"{here}: the feed must be > 0 mm/min")
                feed = value / 60.0
                continue
            if letter in "XYIJ":
                if abs(value) > COORDINATE_LIMIT:
                    raise ProgramError(n, col, raw.strip(), f"{here}: beyond {COORDINATE_LIMIT:g} mm, no "
                                                            "machine is that large")
                values[letter] = value
                continue
            reason = ("R-format arcs are not in the subset: give the centre with I and J" if letter == "R" else
                      "only the XY plane is in the subset (no Z)" if letter == "Z" else
                      "the offset is diameter_delta / 2, not a D word" if letter == "D" else
                      f"word {letter} is not in the subset (G, M, X, Y, I, J, F, N)")
            raise ProgramError(n, col, raw.strip(), f"{here}: {reason}")
        if new_motion is not None:
            motion = new_motion
        has_xy = "X" in values or "Y" in values
        has_ij = "I" in values or "J" in values
        xy_col = min((seen[k] for k in "XY" if k in values), default=1)
        ij_col = min((seen[k] for k in "IJ" if k in values), default=1)
        move_col = motion_col or xy_col                       # the motion word, or the first coordinate
        if has_ij and motion not in (2, 3):
            raise ProgramError(n, ij_col, raw.strip(), "I and J belong to G02/G03 arcs")
        if has_xy or has_ij:
            if motion is None:
                raise ProgramError(n, xy_col, raw.strip(), "a move with no motion mode: give G00, G01, G02 or G03 "
                                                           "first")
            if motion != 0 and feed == 0.0:
                raise ProgramError(n, move_col, raw.strip(), f"G{motion:02d} with no feed: give F (mm/min) first")
            tx = (x + values.get("X", 0.0)) if incremental else values.get("X", x)
            ty = (y + values.get("Y", 0.0)) if incremental else values.get("Y", y)
            if max(abs(tx), abs(ty)) > COORDINATE_LIMIT:
                raise ProgramError(n, xy_col, raw.strip(), f"the move ends at ({tx:g}, {ty:g}): beyond "
                                                           f"{COORDINATE_LIMIT:g} mm, no machine is that large")
            element: Element | None = None
            if motion in (2, 3):
                if not has_ij:
                    raise ProgramError(n, move_col, raw.strip(),
                                       f"G{motion:02d} needs the centre as I and/or J (R-format arcs are not in "
                                       "the subset)")
                cx, cy = x + values.get("I", 0.0), y + values.get("J", 0.0)
                r_start, r_end = math.hypot(x - cx, y - cy), math.hypot(tx - cx, ty - cy)
                if r_start < ARC_RADIUS_TOLERANCE:
                    raise ProgramError(n, ij_col, raw.strip(),
                                       f"I{values.get('I', 0.0):g} J{values.get('J', 0.0):g}: the centre is the "
                                       "start point, no circle")
                if abs(r_start - r_end) > ARC_RADIUS_TOLERANCE:
                    raise ProgramError(n, ij_col, raw.strip(),
                                       f"I/J do not define a circle through start and end: radius {r_start:.4f} mm "
                                       f"to the start, {r_end:.4f} mm to the end (tolerance "
                                       f"{ARC_RADIUS_TOLERANCE:g} mm)")
                if math.hypot(tx - x, ty - y) <= POINT_EPS:
                    tx, ty = x, y                        # ends where it starts (up to rounding): a full circle
                element = arc_through((x, y), (tx, ty), (cx, cy), motion == 3, ARC_RADIUS_TOLERANCE)
                if math.hypot(element.end[0] - tx, element.end[1] - ty) > 1e-12:
                    tx, ty = element.end                 # kept its centre: ends on its circle, near X/Y
            elif math.hypot(tx - x, ty - y) > POINT_EPS:
                element = Line((x, y), (tx, ty))
            if element is not None:
                if comp != comp_moved and isinstance(element, Arc):
                    what = "start" if comp else "end"
                    raise ProgramError(n, move_col, raw.strip(),
                                       f"an arc cannot {what} cutter compensation: program a straight "
                                       f"{'lead-in' if comp else 'lead-out'} move (G00/G01)")
                if len(moves) == MAX_MOVES:
                    raise ProgramError(n, move_col, raw.strip(), f"more than {MAX_MOVES} moves: split the program")
                moves.append(Move(element, motion == 0, feed, n, comp_moved, comp))
                comp_moved = comp
                x, y = tx, ty
        if end_program:
            if comp_moved or comp:
                raise ProgramError(n, seen["M"], raw.strip(), "cutter compensation is still on at the program "
                                                              "end: end it with G40 and a lead-out move")
            ended_at = n
    if not ended_at:
        last = max((n for n, line in enumerate(lines, start=1) if line.strip()), default=1)
        raise ProgramError(last, 1, lines[last - 1].strip(), "the program does not end with M02 or M30")
    if not moves:
        raise ProgramError(ended_at, 1, lines[ended_at - 1].strip(), "the program has no moves")
    return moves

