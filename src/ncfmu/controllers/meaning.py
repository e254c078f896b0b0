"""What a configured controller's program means, as plain data: the one answer the host's readers share.

The controller that runs a program is the one owner of its meaning (LinuxCNC's interpreter and its canon calls):
:class:`~.sequencer.CutSequencer` and :class:`~.contour.ContourInterpolator` publish a :class:`ProgramMeaning`
from ``configure`` (their ``meaning`` attribute) -- the programmed elements with their text lines and N numbers,
the finished outlines the cycles define, the regions they cut away by their definition, the tools the program
uses with their table rows, the setup (stock, homes, work offsets, start) and whether it drives the spindle. The
part check (:mod:`ncfmu.systems.part`), the report's plots (:mod:`ncfmu.systems.report`) and the thread judge read
it; none of them reads the program or the tool table again.

A cycle's region reaches the part check one way: an operation of the lathe program's ``parse`` output with a
``removed()`` method (a simple polygon of (Z, radius) points, the program's coordinates, X as a radius,
:data:`.g7x.FAR` standing for "to the outside") -- gathered here for every such operation, whatever its cycle.

Plain Python (no shapely: the controllers are compiled with mypyc and run in an FMU on the standard library).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from .g7x import FAR, Tool
from .gcode import Block, Move
from .geometry import Element, Point
from .mypyc_compat import mypyc_attr
from .subprograms import run_order


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Programmed:
    """One programmed element: its geometry in the machine's plane ((z, x) on a lathe, (x, y) on a mill), the text
    line of its block (a point path: the segment's number), that block's N number (None: it has none) and whether
    it runs at rapid."""

    element: Element
    line: int
    n: int | None
    rapid: bool


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Outline:
    """A finished outline the program defines: a lathe cycle's profile (G70/G71 P..Q; ``line`` the cycle's block,
    ``start`` its start point (z, x radius), ``inside`` a bore's), or the mill's contour (the moves under
    G41/G42, or the point path; ``line`` its first element's)."""

    line: int
    start: Point
    inside: bool
    elements: tuple[Programmed, ...]


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Region:
    """What one operation cuts away by its definition (its ``removed()``): ``outline`` a simple polygon, ``line``
    the operation's block (0: the registers'), ``edges`` the programmed elements that name a deviation near it
    (a profile's blocks; empty: the outline itself, named by ``line``)."""

    line: int
    outline: tuple[Point, ...]
    edges: tuple[Programmed, ...] = ()


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class ToolUse:
    """A turret station the program uses and the tool table's row its T word gives it (``T0102``: station 1,
    row 2; row 0: no offset), with the row's fields as the controller holds them."""

    station: int
    row: int
    tool: Tool


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Stock:
    """The material the part is cut from: a lathe's bar (``diameter``, ``length`` toward the chuck from its face
    at ``face_z``), or a mill's plate (``margin`` around the contour)."""

    diameter: float = 0.0
    length: float = 0.0
    face_z: float = 0.0
    margin: float = 0.0


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class ProgramMeaning:
    """What a configured controller's program (or its registers, its point path) means.

    ``dialect``: "lathe" or "mill" (a part program), "registers" (the sequencer's blocks), "points" (the
    interpolator's point path). ``elements``: every programmed move in program order (a lathe's as its cycles
    and the nose compensation leave them, the planned passes not included); ``numbers``: text line -> N number.
    ``start`` is (x, z) on a lathe, (x, y) on a mill, as the controller's parameters; ``home`` the lathe's machine
    reference (z, x); ``works`` the work offsets G54..G59 (z, x radius) and ``first_work`` the one the program
    selects first (G54 at power-on). ``drives_spindle``: the program commands the spindle (S, M03/M04/M05), so a
    cut while it stands is a crash (the registers leave the spindle alone). ``x_written``: how a lathe program
    writes X ("diameter", "radius", "diameter and radius"; "" for the registers and the mill)."""

    dialect: str
    start: Point
    elements: tuple[Programmed, ...] = ()
    outlines: tuple[Outline, ...] = ()
    regions: tuple[Region, ...] = ()
    tools: tuple[ToolUse, ...] = ()
    numbers: Mapping[int, int] = field(default_factory=dict)
    stock: Stock = Stock()
    home: Point | None = None
    works: tuple[Point, ...] = ()
    first_work: Point = (0.0, 0.0)
    drives_spindle: bool = False
    x_written: str = ""
    cutter_radius: float = 0.0          # the mill's cutter (the compensation's offset)
    pocket: bool = False                # the mill's contour is a pocket's wall (the part lies around it)

    @property
    def programmed(self) -> bool:
        """A part program is given (not the registers, not a point path)."""
        return self.dialect in ("lathe", "mill")

    @property
    def rapid_lines(self) -> tuple[int, ...]:
        """The program lines of the rapid moves, in order."""
        return tuple(sorted({p.line for p in self.elements if p.rapid}))

    def __deepcopy__(self, memo: dict[int, object]) -> ProgramMeaning:
        # immutable, and large (a region's arcs are points 20 um apart): a copied controller (an FMU state,
        # a retune) shares it
        return self

    def tool(self, station: int) -> ToolUse | None:
        """The use of a turret station (None: the program does not name it)."""
        for use in self.tools:
            if use.station == station:
                return use
        return None


def block_numbers(blocks: Sequence[Block]) -> dict[int, int]:
    """Text line -> N number of every block that has one."""
    return {b.line: b.n for b in blocks if b.n is not None}


def _programmed(move: Move, numbers: Mapping[int, int]) -> Programmed:
    """A move as a programmed element, with its block's N number."""
    return Programmed(move.element, move.line, numbers.get(move.line), move.rapid)


def lathe_meaning(ops: Sequence[object], blocks: Sequence[Block], start: Point, tools: Sequence[Tool],
                  works: Sequence[Point], home: Point, stock: Stock, diameter: bool) -> ProgramMeaning:
    """The meaning of a lathe program: ``ops`` its operations (:func:`.lathe_program.parse`), ``blocks`` its blocks
    as read (text order, every block), ``start`` (x, z), ``tools`` the tool table (row k = tools[k - 1]),
    ``works`` G54..G59, ``home`` (z, x), ``diameter`` the X mode at power-on."""
    numbers = block_numbers(blocks)
    elements: list[Programmed] = []
    outlines: list[Outline] = []
    regions: list[Region] = []
    edges_of: dict[int, tuple[Programmed, ...]] = {}     # id of a profile -> its blocks (one tuple a profile)
    for op in ops:
        if isinstance(op, Move):
            elements.append(_programmed(op, numbers))
            continue
        profile = getattr(op, "profile", None)
        edges: tuple[Programmed, ...] = ()
        if profile is not None:
            key = id(profile)
            if key not in edges_of:
                edges_of[key] = tuple(_programmed(b, numbers) for b in profile.blocks)
            edges = edges_of[key]
            outlines.append(Outline(op.line, op.start,  # type: ignore[attr-defined]
                                    bool(getattr(profile, "inside", False)), edges))
        removed = getattr(op, "removed", None)
        if removed is not None:
            region = Region(op.line, tuple(removed()), edges)  # type: ignore[attr-defined]
            if all(r.outline != region.outline for r in regions):
                regions.append(region)
    rows: dict[int, int] = {0: 0}              # station -> the row its first T word gives it
    first_work = 0
    modes: list[str] = []
    # in the order the CNC runs them: a subprogram the text holds but never calls sets nothing
    for b in run_order(list(blocks)):
        if "T" in b.values:
            station, row = divmod(int(b.values["T"]), 100)
            if station not in rows:
                rows[station] = row
        for g, _ in b.g:
            if 54 <= g <= 59 and not first_work:
                first_work = g - 53
            if g in (7, 8):
                mode = "diameter" if g == 7 else "radius"
                if mode not in modes:
                    modes.append(mode)
    if not modes:
        modes.append("diameter" if diameter else "radius")
    uses = tuple(ToolUse(station, row, tools[row - 1] if row else Tool()) for station, row in rows.items())
    return ProgramMeaning("lathe", start, tuple(elements), tuple(outlines), tuple(regions), uses, numbers, stock,
                          home, tuple(works), works[max(first_work, 1) - 1], True,
                          " and ".join(sorted(modes)))


def registers_meaning(stps: Sequence[Point], passes: Sequence[tuple[float, float, float]], start: Point,
                      tools: Sequence[Tool], works: Sequence[Point], home: Point, stock: Stock) -> ProgramMeaning:
    """The meaning of the sequencer's registers: each block's deepest pass (``passes``: the pass's depth below its
    start point, its X and Z components Xp, Zp) from its start point ``stps`` (x, z) cuts away all above it."""
    regions = []
    for (x0, z0), (depth, xp, zp) in zip(stps, passes):
        # the deepest pass: from (z0, x0 - depth) to (z0 - Zp, x0 - depth - Xp); above it is cut away
        regions.append(Region(0, ((z0, x0 - depth), (z0 - zp, x0 - depth - xp), (z0 - zp, FAR), (z0, FAR))))
    return ProgramMeaning("registers", start, regions=tuple(regions), tools=(ToolUse(0, 0, Tool()),), stock=stock,
                          home=home, works=tuple(works), first_work=works[0])


def mill_meaning(moves: Sequence[Move], blocks: Sequence[Block], start: Point, cutter_radius: float, margin: float,
                 pocket: bool) -> ProgramMeaning:
    """The meaning of a mill program: ``moves`` its moves (:func:`.rs274.parse`), the contour the ones under
    G41/G42 on both ends."""
    numbers = block_numbers(blocks)
    elements = tuple(_programmed(m, numbers) for m in moves)
    chain = tuple(p for p, m in zip(elements, moves) if m.comp_before != 0 and m.comp_after != 0)
    outlines = (Outline(chain[0].line, chain[0].element.start, False, chain),) if chain else ()
    return ProgramMeaning("mill", start, elements, outlines, numbers=numbers, stock=Stock(margin=margin),
                          cutter_radius=cutter_radius, pocket=pocket)


def points_meaning(contour: Sequence[Element], start: Point, cutter_radius: float, margin: float,
                   pocket: bool) -> ProgramMeaning:
    """The meaning of the interpolator's point path: its segments, numbered from 1, are the contour."""
    elements = tuple(Programmed(e, k, None, False) for k, e in enumerate(contour, start=1))
    outlines = (Outline(1, elements[0].element.start, False, elements),) if elements else ()
    return ProgramMeaning("points", start, elements, outlines, stock=Stock(margin=margin),
                          cutter_radius=cutter_radius, pocket=pocket)
