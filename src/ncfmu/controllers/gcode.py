"""One G-code front end for every machine: reading and checking the words (LinuxCNC's interp_read and
interp_check), the one move record, and the arc every machine builds the same way.

A machine's language is a :class:`Dialect` -- data: its G codes and their modal groups, the codes it refuses and
why, its M codes, its address letters. :func:`read` turns a program into :class:`Block` s and checks every word
against the dialect: each letter once a block (G excepted), N first and whole (and, where P/Q find blocks by it,
once a program), G codes of the dialect and one per modal group, M codes of the dialect, F > 0, coordinates
within :data:`COORDINATE_LIMIT`, nothing after the program end, an end. It reports **every** such error of the
program at once, in line order (:class:`~ncfmu.errors.ProgramErrors`), each with its line and column; a block
with an error is skipped. What a block *does* -- modes, positions, arcs, cycles -- is the machine's conversion:
:mod:`.rs274` (the mill, XY, cutter compensation) and :mod:`.lathe_program` (the lathe, XZ), with the lathe's
cycles in :mod:`.g7x`. Conversion stops at its first error (a position after a wrong block means nothing).

Adding a word: its entry in the dialect's table here (and, when it does something, its conversion).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field

from ..errors import ProgramError, ProgramErrors
from .geometry import Element, Point, arc_through
from .mypyc_compat import mypyc_attr

#: Programs longer than this are refused (characters): a part program for one part is far shorter.
MAX_PROGRAM_CHARS = 200_000
#: Points closer than this are one point (mm): a move shorter is no move (rounding of G91 sums).
POINT_EPS = 1e-9
#: Radii from the centre to the start and to the end of an arc may differ by this much (mm), as
#: LinuxCNC's arc check. The centre moves onto the chord's bisector when that is at most this far, so the
#: arc runs through both points; else (short chords) it keeps its centre and radius and ends on its circle
#: toward the programmed end point, at most this far from it, and the next block starts there.
ARC_RADIUS_TOLERANCE = 0.002
#: A coordinate beyond this is refused (mm): no machine axis is that long.
COORDINATE_LIMIT = 1.0e5

_WORD = re.compile(r"([A-Za-z])[ \t]*([+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+))?")
#: M codes that end a program.
PROGRAM_END = frozenset({2, 30})


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Dialect:
    """A machine's words, as data: what :func:`read` accepts and the reason it gives for what it refuses."""

    name: str
    groups: Mapping[int, str]            # G code -> its modal group ("motion (G00-G03)", ...)
    refused_g: Mapping[int, str]         # G code -> why it is refused
    g_list: str                          # the G codes, for messages
    m_codes: frozenset[int]              # the M codes taken
    m_list: str
    coordinates: str                     # address letters carrying a length (checked against COORDINATE_LIMIT)
    refused_letters: Mapping[str, str]   # letter -> why it is refused
    letter_list: str                     # the letters taken, for messages
    unique_numbers: bool = False         # N numbers name blocks (G70/G71 P and Q): each at most once
    block_delete: bool = False           # a block may start with '/' (block delete, skipped with the switch on)
    subprograms: bool = False            # after the main program's end, further O programs ending with M99
    comma_letters: str = ""              # letters also taken after a comma (Fanuc's ,C ,R): the word is ",C"
    # the plane's axes, its first coordinate first: (absolute letter, incremental letter or "") -- the lathe's
    # (Z, W), (X, U); the mill's (X, ""), (Y, "")
    axes: tuple[tuple[str, str], ...] = ()


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Move:
    """One programmed move: its geometry (in the machine's plane) and how it is run -- the one move record of
    every machine (the mill's with the cutter compensation around it, a lathe profile's with its text)."""

    element: Element
    rapid: bool             # G00: at the rapid rate, not the programmed feed
    feed: float             # programmed feed, mm/s (for G00: the last F, unused; 0: none in force)
    line: int               # program line (1-based)
    comp_before: int = 0    # cutter compensation in force before the move: 0 off, +1 left, -1 right
    comp_after: int = 0     # ... and after it (a change is a lead-in or a lead-out)
    raw: str = field(default="", compare=False)      # the block as written (for messages)


#: G40 / G41 / G42: the cutter (mill) or tool-nose (lathe) radius compensation's side, 0 off, +1 left of travel,
#: -1 right.
COMP_SIDE = {40: 0, 41: 1, 42: -1}


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass
class Modes:
    """The modal state of a program's conversion, one for every dialect (LinuxCNC's setup block, as
    interp_convert keeps it): the motion mode (G00-G03, a dialect's own motion codes), the distance mode
    (G90/G91), the X mode (G7/G8: X a diameter; the mill has none), the feed (F, mm/s; 0 until one) and the
    compensation's side (:data:`COMP_SIDE`). A dialect's own modes extend it (the lathe's machine state)."""

    motion: int | None = None
    incremental: bool = False
    diameter: bool = False
    feed: float = 0.0       # mm/s (a lathe under G99: mm/s per rev/min)
    comp: int = 0

    def distance_and_x(self, b: Block) -> None:
        """The block's G90/G91 and G7/G8, read before its words as every move reads them."""
        for g, _ in b.g:
            if g in (90, 91):
                self.incremental = g == 91
            elif g in (7, 8):
                self.diameter = g == 7

    def feed_word(self, b: Block) -> None:
        """The block's F (mm/min), modal: a cycle's too (RS274)."""
        if "F" in b.values:
            self.feed = b.values["F"] / 60.0

    def end(self, b: Block, here: Point, axes: tuple[tuple[str, str], ...]) -> Point:
        """Where a move of block ``b`` from ``here`` ends, in the plane of ``axes`` (a dialect's): on each axis its
        absolute word, or ``here`` plus its incremental word (or plus the absolute word under G91), or ``here``;
        X a diameter (halved) under G7."""
        out: list[float] = []
        v = b.values
        for (absolute, incremental), at in zip(axes, here):
            scale = 0.5 if self.diameter and absolute == "X" else 1.0
            if incremental and incremental in v:
                out.append(at + scale * v[incremental])
            elif absolute in v:
                out.append(at + scale * v[absolute] if self.incremental else scale * v[absolute])
            else:
                out.append(at)
        return (out[0], out[1])


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass
class Block:
    """One checked block: its words in order, its number, its G and M codes and its other words' values."""

    line: int
    raw: str
    words: list[tuple[str, float, str, int]]      # (letter, value, spelled number, column)
    n: int | None = None
    g: list[tuple[int, int]] = field(default_factory=list)         # (code, column), in order
    m: list[tuple[int, int]] = field(default_factory=list)
    values: dict[str, float] = field(default_factory=dict)          # every other letter but N: its value

    def col(self, letter: str) -> int:
        """The column of the block's first ``letter`` (1 when it has none)."""
        return next((c for w, _, _, c in self.words if w == letter), 1)

    def err(self, col: int, reason: str) -> ProgramError:
        return ProgramError(self.line, col, self.raw.strip(), reason)

    @property
    def ends(self) -> bool:
        return any(code in PROGRAM_END for code, _ in self.m)


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


#: G codes of Fanuc's controls that no dialect here takes, named in the refusal as the manuals name them (a
#: programmer reading "G112: not in the subset (polar interpolation)" knows what the line asked for).
NAMED_G = {107: "cylindrical interpolation", 112: "polar interpolation", 113: "polar interpolation cancel",
           68: "coordinate rotation", 69: "coordinate rotation cancel", 10: "programmable data input"}

#: Fanuc's direct drawing dimension input: a comma word after a move's end point (``,C1.`` a chamfer, ``,R2.`` a
#: corner radius, ``,A30.`` the move's angle), as the Fanuc manuals name them.
DIRECT_DRAWING = {"C": "chamfer", "R": "corner radius", "A": "angle"}


def _direct_drawing(word: str) -> str:
    """Why a comma word is refused: ``,C: not in the subset (chamfer by direct drawing dimensions)``."""
    what = DIRECT_DRAWING.get(word[1:2].upper())
    return (f"{word.upper()}: not in the subset ({what} by direct drawing dimensions)" if what else
            f"{word!r}: a comma word (direct drawing dimensions) is not in the subset")


def words(text: str, line_no: int, comma_letters: str = "") -> list[tuple[str, float, str, int]]:
    """(letter, value, spelled number, column) of every word of a comment-free line; a comma before one of
    ``comma_letters`` makes a word of its own (letter ",C")."""
    found, col = [], 0
    while col < len(text):
        if text[col].isspace():
            col += 1
            continue
        comma = text[col] == "," and text[col + 1:col + 2].upper() in comma_letters and col + 1 < len(text)
        m = _WORD.match(text, col + 1 if comma else col)
        if not m or not m.group(1):
            ch = text[col]
            reason = ("parameters and expressions are not in the subset" if ch in "#[]=" else
                      "block delete '/' is not in the subset" if ch == "/" else
                      _direct_drawing(text[col:col + 2]) if ch == "," else f"unexpected character {ch!r}")
            raise ProgramError(line_no, col + 1, text.strip(), reason)
        letter = ("," if comma else "") + m.group(1).upper()
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


#: What ends a line of a program, all alike: LF, CR LF, CR alone (old Macs, tape punch formats), NEL (U+0085) and
#: Unicode's line and paragraph separators (U+2028, U+2029). A program reads the same, with the same line numbers,
#: whatever wrote it; a CR followed by an LF is one line end.
LINE_END = re.compile("\r\n|[\n\r\x85\u2028\u2029]")
#: What str.splitlines (and tools built on it) also takes for a line end and this reader does not: a program
#: holding one would read as other lines elsewhere, so it is refused wherever it stands, naming the character.
NOT_LINE_ENDS = {"\x0b": "a vertical tab (U+000B)", "\x0c": "a form feed (U+000C)",
                 "\x1c": "a file separator (U+001C)", "\x1d": "a group separator (U+001D)",
                 "\x1e": "a record separator (U+001E)"}
_NOT_LINE_END = re.compile("[\x0b\x0c\x1c\x1d\x1e]")


def program_lines(text: str) -> list[str]:
    """A program's lines, after its length check, split at every :data:`LINE_END`; ProgramError at the first of
    :data:`NOT_LINE_ENDS` (its line and column)."""
    if len(text) > MAX_PROGRAM_CHARS:
        raise ProgramError(1, 1, f"<{len(text)} characters>", f"longer than {MAX_PROGRAM_CHARS} characters")
    lines = LINE_END.split(text)
    if _NOT_LINE_END.search(text):
        for n, line in enumerate(lines, start=1):
            found = _NOT_LINE_END.search(line)
            if found:
                raise ProgramError(n, found.start() + 1, line.strip(), f"{NOT_LINE_ENDS[found.group()]} is neither a "
                                   "line end (LF, CR LF, CR, NEL, U+2028, U+2029) nor a blank in a program")
    return lines


def check_once(seen: dict[str, int], i: int, letter: str, col: int, n: int, raw: str) -> None:
    """Word ``i`` of a block, at column ``col``: each letter but G at most once a block (``seen``: letter ->
    first column), and N only as the first word."""
    if letter in seen and letter != "G":
        raise ProgramError(n, col, raw.strip(), f"{letter} given twice in one block (first at column {seen[letter]})")
    seen.setdefault(letter, col)
    if letter == "N" and i != 0:
        raise ProgramError(n, col, raw.strip(), "the block number N must be the first word")


def check(b: Block, dialect: Dialect) -> None:
    """Check the words of block ``b`` against the dialect, in the order written; fill its number, codes and
    values. Raises the block's first error."""
    seen: dict[str, int] = {}
    groups: dict[str, int] = {}
    for i, (letter, value, spelled, col) in enumerate(b.words):
        word = f"{letter}{spelled}"
        check_once(seen, i, letter, col, b.line, b.raw)
        if letter == "N":
            if value != int(value) or value < 0:
                raise b.err(col, f"N{spelled}: a block number is a whole number >= 0")
            b.n = int(value)
        elif letter == "G":
            named = int(value) in NAMED_G and int(value) not in dialect.groups and int(value) not in dialect.refused_g
            if value == int(value) and named:
                raise b.err(col, f"{word}: not in the subset ({NAMED_G[int(value)]})")
            if value != int(value) or value > 99:
                raise b.err(col, f"{word} is not in the subset")
            g = int(value)
            if g in dialect.refused_g:
                raise b.err(col, f"{word}: {dialect.refused_g[g]}")
            if g not in dialect.groups:
                raise b.err(col, f"{word} is not in the subset ({dialect.g_list})")
            group = dialect.groups[g]
            if group in groups:
                raise b.err(col, f"G{groups[group]:02d} and {word} in one block: both belong to the modal group "
                                 f"{group}")
            groups[group] = g
            b.g.append((g, col))
        elif letter == "M":
            if value != int(value) or int(value) not in dialect.m_codes:
                raise b.err(col, f"M{spelled} is not in the subset ({dialect.m_list})")
            b.m.append((int(value), col))
        elif letter == "F":
            if not value > 0:
                raise b.err(col, f"{word}: the feed must be > 0 mm/min")
            b.values["F"] = value
        elif letter in dialect.coordinates or (letter[0] == "," and letter[1:] in dialect.comma_letters):
            if abs(value) > COORDINATE_LIMIT:
                raise b.err(col, f"{word}: beyond {COORDINATE_LIMIT:g} mm, no machine is that large")
            b.values[letter] = value
        else:
            reason = dialect.refused_letters.get(letter, f"word {letter} is not in the subset ({dialect.letter_list})")
            raise b.err(col, f"{word}: {reason}")


def _slash(clean: str, n: int, raw: str) -> tuple[str, bool]:
    """A comment-free line without its block-delete slash, and whether it had one (at its start only)."""
    lead = len(clean) - len(clean.lstrip())
    deleted = clean[lead:lead + 1] == "/"
    if deleted:
        clean = clean[:lead] + " " + clean[lead + 1:]
    if "/" in clean:
        raise ProgramError(n, clean.index("/") + 1, raw.strip(), "block delete '/' stands at the start of a block "
                                                                "(/N10 G01 ...), once")
    return clean, deleted


def read(text: str, dialect: Dialect, block_delete: bool = False) -> list[Block]:
    """The checked blocks of a program (empty lines, comment-only lines and ``%`` lines left out); with
    ``block_delete`` (the switch on) also the blocks that start with ``/`` (a dialect's with block delete: they are
    checked either way, so a program reads the same with the switch on or off).

    Raises
    ------
    ProgramError
        for one error; :class:`~ncfmu.errors.ProgramErrors` (a ProgramError, with the first one's line and
        column) for several -- every error of the program, in line order, each naming its line and column.
    """
    lines = program_lines(text)
    out: list[Block] = []
    errors: list[ProgramError] = []
    numbered: dict[int, int] = {}           # block number -> line (of the program it is in)
    ended_at = 0
    sub_at = 0                              # the line of the subprogram being read (0: the main program)
    for n, raw in enumerate(lines, start=1):
        if raw.strip() == "%":
            continue
        try:
            clean = strip_comments(raw, n)
            if ended_at:
                if not clean.strip():
                    continue
                if not (dialect.subprograms and clean.lstrip()[:1].upper() == "O"):
                    raise ProgramError(n, len(clean) - len(clean.lstrip()) + 1, raw.strip(),
                                       f"text after the program end (line {ended_at})" +
                                       (": a subprogram starts with O<number>" if dialect.subprograms else ""))
                ended_at, sub_at, numbered = 0, n, {}
            deleted = False
            if dialect.block_delete:
                clean, deleted = _slash(clean, n, raw)
            found = words(clean, n, dialect.comma_letters)
            if not found:
                continue
            b = Block(n, raw, found)
            check(b, dialect)
        except ProgramError as err:
            errors.append(err)
            continue
        if deleted and block_delete:
            continue
        if dialect.unique_numbers and b.n is not None:
            if b.n in numbered:
                errors.append(b.err(b.col("N"), f"N{b.n} again: line {numbered[b.n]} is N{b.n} (a block number "
                                                "names one block: G70/G71 P and Q find the profile by it)"))
                continue
            numbered[b.n] = n
        if sub_at and b.ends:
            errors.append(b.err(b.col("M"), f"M02/M30 in the subprogram of line {sub_at}: a subprogram ends with "
                                            "M99 (return to the calling block)"))
            continue
        if b.ends or (sub_at and any(code == 99 for code, _ in b.m)):
            ended_at = n
        out.append(b)
    if not ended_at:
        last = max((n for n, line in enumerate(lines, start=1) if line.strip()), default=1)
        errors.append(ProgramError(last, 1, lines[last - 1].strip(),
                                   f"the subprogram of line {sub_at} does not end with M99" if sub_at else
                                   "the program does not end with M02 or M30"))
    if len(errors) == 1:
        raise errors[0]
    if errors:
        raise ProgramErrors(errors)
    return out


def arc(b: Block, start: Point, end: Point, centre: Point, ccw: bool, col: int, centre_words: str) -> tuple[
        Element, Point]:
    """The G02/G03 arc of block ``b`` from ``start`` toward ``end`` about ``centre`` (in the machine's plane,
    counter-clockwise there when ``ccw``), after RS274's circle check; and the point it ends at (``end``, or on
    its circle near it when the centre is kept, see :data:`ARC_RADIUS_TOLERANCE`). ``centre_words``: how the
    block gave the centre ("I/J", "I/K" ...), for messages at column ``col``."""
    r0, r1 = math.dist(start, centre), math.dist(end, centre)
    if r0 < ARC_RADIUS_TOLERANCE:
        given = " ".join(f"{k}{b.values.get(k, 0.0):g}" for k in centre_words.split("/"))
        raise b.err(col, f"{given}: the centre is the start point, no circle")
    if abs(r0 - r1) > ARC_RADIUS_TOLERANCE:
        raise b.err(col, f"{centre_words} do not define a circle through start and end: radius {r0:.4f} mm to the "
                         f"start, {r1:.4f} mm to the end (tolerance {ARC_RADIUS_TOLERANCE:g} mm)")
    if math.dist(start, end) <= POINT_EPS:
        end = start                                  # ends where it starts (up to rounding): a full circle
    element = arc_through(start, end, centre, ccw, ARC_RADIUS_TOLERANCE)
    return element, element.end if math.dist(element.end, end) > 1e-12 else end
