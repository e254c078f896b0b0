"""The part check of a run: did it crash, and is the part it made within tolerance of the programmed part.

A report part (:class:`LathePart`, :class:`MillPart`) like the others of :mod:`.report`: its accumulator reads
the recorded rows chunk by chunk -- the servo axes' *actual* positions, the controller's program line and
whether the move is at rapid -- and feeds them to the material-removal engine (:mod:`ncfmu.machining`), which
keeps the stock left and the crashes, never the trajectory. Everything it needs besides is what the controller
configured with the run's parameters publishes (its ``meaning``, :mod:`ncfmu.controllers.meaning`; the part check
reads no program and no tool table itself): the bar stock and the tools the program uses of a lathe, with the
chuck jaws (the limiter's regions with a lower X bound); the plate (``contour.stock_margin`` around the contour)
and the cutter (the compensation's radius) of a mill; and the programmed part: the stock less the regions the
lathe's operations cut away by their definition (each operation's ``removed()``: G71/G70's all above the profile,
G72/G73's profiles, G74's drilled hole, G75's groove, a G90/G94 pass; the registers' all above each block's
deepest pass), the mill's closed contour.

Inside work: a G71/G70 profile that rises from the start point's X (a bore, :mod:`..controllers.g7x`) is judged
as a bore -- the stock a tube whose drilled hole's radius is the bore cycle's start point's X (no parameter: the
boring bar enters at the hole), the part the material above the profile (what lies between the profile and the
hole is cut away), the tool mirrored (nose on top, the bar below it, a hole's radius high), and instead of the
spindle axis the bore's far wall (the bar reaching through the hole) is forbidden.

The tool's nose radius and deepest cut come from :class:`PartSettings` (the tool table's, when there is one):
0 is a sharp point, ``max_depth`` unlimited unless given. The verdict (:class:`PartVerdict`) is judged at the
end of the run: crashes (time, program line, what, depth), the largest excess and gouge against the programmed
part with where and which program line, and whether the part is within ``tolerance``. A part whose cycle did
not finish is not judged (its crashes still count).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..controllers.base import POSITION_LIMIT
from ..controllers.g7x import ARC_SPACING, FAR
from ..controllers.meaning import ProgramMeaning, Programmed
from ..controllers.peck_cycles import DRILL_POINT
from ..machining import (
    Crash,
    Cutter,
    Deviation,
    MaterialRemoval,
    deviation,
    drill,
    grooving_insert,
    lathe_tool,
    mill_cutter,
    placed,
    turning_insert,
)
from ..machining.removal import BLADE, Forbidden
from ..ports import to_float, to_int
from .report import (
    FirstTime,
    Parameters,
    Part,
    PartAccumulator,
    Report,
    ReportAccumulator,
    columns_of,
    configured,
    table_of,
)
from .threads import ThreadJudge, ThreadResult, thread_judge

#: The default tolerance of the part against the programmed part (mm): ``--tolerance``.
TOLERANCE = 0.01
#: How many crash lines a summary prints (the JSON keeps up to the engine's MAX_CRASHES).
CRASH_LINES = 5
#: The spindle stands (a cut then is a crash) below the larger of these: an absolute speed (rev/min) and a
#: fraction of the commanded speed. Why: 1 rev/min is a revolution a minute -- at the slowest feed a program
#: writes (F 1 mm/min, G98) a chip of 1 mm a revolution, ten times what a finishing insert takes (0.05-0.3 mm/rev):
#: below it the tool pushes into a bar that does not turn. 1 % of the command is a spindle that has not started
#: or has stalled -- the sequencer begins a cut only within its speed-arrival band (``seq.spindle_band`` 5 %),
#: so a cut at speed is never flagged; after M05 the command is 0 and 1 rev/min decides (a spindle still running
#: down from M05 turns, and cuts, until then).
STANDSTILL_RPM = 1.0
STANDSTILL_FRACTION = 0.01


@dataclass(frozen=True)
class PartSettings:
    """How the part is judged: ``tolerance`` (mm), and the lathe tools' ``nose_radius`` (mm, 0: a sharp corner)
    and ``max_depth`` (mm, the deepest radial engagement a tool may take; inf: no limit). None: each tool's from
    the tool table (``seq.tool[k].nose_radius``, ``seq.tool[k].max_depth`` of the row its T word names), else 0
    and no limit; given, they stand for every tool's."""

    tolerance: float = TOLERANCE
    nose_radius: float | None = None
    max_depth: float | None = None
    drawing: Any = None       # the part drawn (a systems.drawing.Drawing, --drawing): judged against in place of
                              # the programmed part


@dataclass
class PartVerdict:
    """What the part check says about a run (``OUT/<system>.part.json``, ``result.part`` in the pytest plugin)."""

    crashes: list[Crash]
    crash_count: int
    tolerance_mm: float
    judged: str                           # "" when judged, else why not ("the cycle did not finish", ...)
    max_left_mm: float = math.nan
    max_gouge_mm: float = math.nan
    left_at: tuple[float, float] | None = None
    gouge_at: tuple[float, float] | None = None
    left_line: int = 0
    gouge_line: int = 0
    axes: tuple[str, str] = ("u", "v")    # the names of the plane's coordinates (Z, X or X, Y)
    numbers: dict[int, int] = field(default_factory=dict, repr=False)   # text line -> its block's N number
    made: Any = field(default=None, repr=False)          # the part as made (a shapely geometry), for the plot
    programmed: Any = field(default=None, repr=False)    # the programmed part
    threads: list[ThreadResult] = field(default_factory=list)   # the program's threads (systems/threads.py)

    @property
    def crashed(self) -> bool:
        return self.crash_count > 0

    @property
    def within_tolerance(self) -> bool | None:
        """False on a crash or a part out of tolerance; None when the part was not judged (and nothing crashed)."""
        if self.crashed or any(t.cross_threaded for t in self.threads):
            return False
        if self.judged:
            return None
        return self.max_left_mm <= self.tolerance_mm and self.max_gouge_mm <= self.tolerance_mm

    def as_json(self) -> dict[str, object]:
        def number(v: float) -> float | None:
            return None if math.isnan(v) else v

        return {"crashes": [{**c.as_dict(), "n": self.numbers.get(c.line)} for c in self.crashes],
                "crash_count": self.crash_count,
                "max_left_mm": number(self.max_left_mm), "max_gouge_mm": number(self.max_gouge_mm),
                "tolerance_mm": self.tolerance_mm, "within_tolerance": self.within_tolerance,
                "left_at": self._where(self.left_at, self.left_line),
                "gouge_at": self._where(self.gouge_at, self.gouge_line), "not_judged": self.judged or None,
                "threads": [t.as_json() for t in self.threads]}

    def _where(self, at: tuple[float, float] | None, line: int) -> dict[str, object] | None:
        if at is None:
            return None
        return {self.axes[0]: at[0], self.axes[1]: at[1], "line": line, "n": self.numbers.get(line)}

    def line_name(self, line: int) -> str:
        """A program line as a user finds it: the text's line, and its block's N number where it has one
        (``line 7 (N70)``)."""
        n = self.numbers.get(line)
        return f"line {line}" + (f" (N{n})" if n is not None else "")

    def _place(self, at: tuple[float, float] | None, line: int) -> str:
        if at is None:
            return ""
        return (f" at {self.axes[0]} {at[0]:.3f} {self.axes[1]} {at[1]:.3f}"
                + (f" ({self.line_name(line)})" if line else ""))

    def summary(self) -> list[str]:
        lines = [f"  part: CRASH at t = {c.t:.3f} s, {self.line_name(c.line)}: {c.what}, {c.depth_mm:.3g} mm deep"
                 for c in self.crashes[:CRASH_LINES]]
        if self.crash_count > CRASH_LINES:
            lines.append(f"  part: ... {self.crash_count - CRASH_LINES} more crashes (OUT/<system>.part.json)")
        tol = f"{self.tolerance_mm:.4f} mm"
        if self.judged:
            lines.append(f"  part: not judged: {self.judged}")
        elif self.crashed and self.max_left_mm <= self.tolerance_mm and self.max_gouge_mm <= self.tolerance_mm:
            # the shape came out right, but a crashed part is no good part: never "within" after a crash
            crashes = f"{self.crash_count} crash{'es' if self.crash_count != 1 else ''}"
            lines.append(f"  part: REJECTED, it crashed ({crashes}); its shape: left <= {self.max_left_mm:.4f} mm, "
                         f"gouge <= {self.max_gouge_mm:.4f} mm")
        elif self.max_left_mm <= self.tolerance_mm and self.max_gouge_mm <= self.tolerance_mm:
            lines.append(f"  part: within {tol}: left <= {self.max_left_mm:.4f} mm, "
                         f"gouge <= {self.max_gouge_mm:.4f} mm")
        else:
            left = (f"left {self.max_left_mm:.4f} mm{self._place(self.left_at, self.left_line)}"
                    if self.max_left_mm > self.tolerance_mm else f"left <= {self.max_left_mm:.4f} mm")
            gouge = (f"gouge {self.max_gouge_mm:.4f} mm{self._place(self.gouge_at, self.gouge_line)}"
                     if self.max_gouge_mm > self.tolerance_mm else f"gouge <= {self.max_gouge_mm:.4f} mm")
            lines.append(f"  part: OUT OF TOLERANCE {tol}: {left}, {gouge}")
        return lines + [t.summary() for t in self.threads]

    def metrics(self) -> dict[str, float]:
        within = self.within_tolerance
        return {"part_crashes": float(self.crash_count), "max_left_mm": self.max_left_mm,
                "max_gouge_mm": self.max_gouge_mm,
                "within_tolerance": math.nan if within is None else float(within)}


@dataclass(frozen=True)
class Setup:
    """What the engine and the verdict need, from a run's parameters."""

    removal: MaterialRemoval
    programmed: Any                       # the programmed part (a shapely polygon), None: nothing to judge against
    anchor: Any                           # what of the stock is the part (the chuck's end, the contour)
    lines: list[tuple[Any, int]]          # (shapely geometry of a programmed element, its program line)
    why_not: str = ""                     # why the part cannot be judged at all
    rapid_lines: tuple[int, ...] | None = None     # the program lines at rapid, when no output says so
    spindle_checked: bool = False         # a cut while the spindle stands is a crash (a program drives it)
    numbers: dict[int, int] = field(default_factory=dict)   # text line -> its block's N number


class PartCheck(Part):
    """A report part that judges the part a run made (the lathe's, the mill's, the grinder's)."""

    settings: PartSettings


class _Judging(PartAccumulator):
    """An accumulator whose run ends in a verdict on the part."""

    def verdict(self) -> PartVerdict:
        raise NotImplementedError

    def summary(self) -> list[str]:
        return self.verdict().summary()

    def metrics(self) -> dict[str, float]:
        return self.verdict().metrics()


class _PartCheckAccumulator(_Judging):
    """Feeds the engine chunk by chunk; judges the part when asked (and again only after more rows)."""

    part: MachinedPart

    def __init__(self, part: MachinedPart, parameters: Parameters) -> None:
        super().__init__(part)
        self.setup = part.setup(parameters)
        self.done = FirstTime()
        self._verdict: PartVerdict | None = None
        self.threads = part.threads(parameters)

    def write(self, rows: np.ndarray) -> None:
        super().write(rows)
        p = self.part
        u, v = p.plane_columns()
        line = rows[p.line_column()]
        rapid = (rows[p.rapid_column()] if self.setup.rapid_lines is None
                 else np.isin(line, np.array(self.setup.rapid_lines, dtype=np.int64)))
        standing = p.standing(rows) if self.setup.spindle_checked else None
        self.setup.removal.write(rows["time"], rows[u], rows[v], rapid, line, standing, p.tools(rows))
        self.done.write(rows["time"], rows[p.done_column()])
        if self.threads is not None:
            self.threads.write(rows)
        self._verdict = None

    def verdict(self) -> PartVerdict:
        if self._verdict is None:
            self._verdict = self.part.judge(self.setup, finished=not math.isnan(self.done.value))
            if self.threads is not None:
                self._verdict.threads = self.threads.results()
        return self._verdict


class MachinedPart(PartCheck):
    """The part check's share of a report (the lathe's and the mill's are below)."""

    settings: PartSettings
    axes: tuple[str, str]

    def plane_columns(self) -> tuple[str, str]:
        raise NotImplementedError

    def line_column(self) -> str:
        raise NotImplementedError

    def done_column(self) -> str:
        raise NotImplementedError

    def rapid_column(self) -> str:
        """The output that says the move is at rapid (a part without one gives its Setup's rapid_lines)."""
        raise NotImplementedError

    def setup(self, parameters: Parameters) -> Setup:
        raise NotImplementedError

    def standing(self, rows: np.ndarray) -> np.ndarray | None:
        """Per row: the work stands (a cut is a crash); None: nothing turns the work."""
        return None

    def tools(self, rows: np.ndarray) -> np.ndarray | None:
        """Per row: the number of the tool at work (the engine's ``tools``); None: the one tool."""
        return None

    def accumulator(self, parameters: Parameters) -> PartAccumulator:
        return _PartCheckAccumulator(self, parameters)

    def threads(self, parameters: Parameters) -> ThreadJudge | None:
        """The judge of the program's threads (systems/threads.py); None: nothing threads."""
        return None

    def judge(self, setup: Setup, finished: bool) -> PartVerdict:
        m = setup.removal
        verdict = PartVerdict(list(m.crashes), m.crash_count, self.settings.tolerance, "", axes=self.axes,
                              numbers=setup.numbers)
        if setup.programmed is None:
            verdict.judged = setup.why_not or "no programmed part to judge against"
            return verdict
        made = m.part(setup.anchor)
        verdict.made, verdict.programmed = made, setup.programmed
        if not finished:
            verdict.judged = "the cycle did not finish"
            return verdict
        d: Deviation = deviation(made, setup.programmed)
        verdict.max_left_mm, verdict.max_gouge_mm = d.left, d.gouge
        verdict.left_at, verdict.gouge_at = d.left_at, d.gouge_at
        verdict.left_line, verdict.gouge_line = _line_at(setup, d.left_at), _line_at(setup, d.gouge_at)
        return verdict


def _line_at(setup: Setup, at: tuple[float, float] | None) -> int:
    """The program line of the programmed element nearest to ``at`` (0: none)."""
    if at is None or not setup.lines:
        return 0
    import shapely
    point = shapely.Point(at)
    return min(setup.lines, key=lambda gl: gl[0].distance(point))[1]


def _elements_polyline(elements) -> list[tuple[float, float]]:
    from ..controllers.geometry import sample
    return [(float(a), float(b)) for a, b in sample(list(elements), ARC_SPACING)]


@dataclass(frozen=True)
class LathePart(MachinedPart):
    """A CutSequencer turning a bar with its radius axis ``x`` and length axis ``z``; the chuck jaws are the
    ``limiter``'s regions with a lower X bound."""

    seq: str
    x: str
    z: str
    limiter: str | None = None
    settings: PartSettings = PartSettings()
    axes: tuple[str, str] = ("Z", "X")
    spindle: str | None = None            # the spindle drive whose actual speed turns the bar

    def variables(self) -> tuple[str, ...]:
        spindle = (f"{self.spindle}.speed", f"{self.seq}.s_cmd", f"{self.seq}.spindle_dir") if self.spindle else ()
        threads = (f"{self.seq}.threading", f"{self.spindle}.revolutions") if self.spindle else ()
        return (*(f"{self.seq}.{v}" for v in ("rapid", "line", "done", "tool")), f"{self.x}.pos", f"{self.z}.pos",
                *spindle, *threads)

    def tools(self, rows: np.ndarray) -> np.ndarray | None:
        """The turret station at work (the sequencer's ``tool`` output: the T word in force)."""
        return rows[f"{self.seq}.tool"]

    def threads(self, parameters: Parameters) -> ThreadJudge | None:
        if self.spindle is None:
            return None
        from ..controllers.sequencer import CutSequencer
        plan = configured(CutSequencer, parameters.get(self.seq, {})).plan
        return thread_judge(plan, self.seq, self.x, self.z, self.spindle, self.settings.tolerance)

    def standing(self, rows: np.ndarray) -> np.ndarray | None:
        """The spindle stands: |actual speed| below STANDSTILL_RPM and below STANDSTILL_FRACTION of the speed
        commanded (the sequencer's S output while its direction is not M05)."""
        if self.spindle is None:
            return None
        commanded = np.abs(rows[f"{self.seq}.s_cmd"]) * (rows[f"{self.seq}.spindle_dir"] != 0)
        return np.abs(rows[f"{self.spindle}.speed"]) < np.maximum(STANDSTILL_RPM, STANDSTILL_FRACTION * commanded)

    def plane_columns(self) -> tuple[str, str]:
        return f"{self.z}.pos", f"{self.x}.pos"

    def line_column(self) -> str:
        return f"{self.seq}.line"

    def done_column(self) -> str:
        return f"{self.seq}.done"

    def rapid_column(self) -> str:
        return f"{self.seq}.rapid"

    def setup(self, parameters: Parameters) -> Setup:
        from shapely.geometry import Polygon, box

        from ..controllers.sequencer import CutSequencer
        meaning: ProgramMeaning = configured(CutSequencer, parameters.get(self.seq, {})).meaning
        radius = meaning.stock.diameter / 2.0
        length = meaning.stock.length
        face = meaning.stock.face_z
        hole = 0.0                        # the radius of the stock's drilled hole (0: a solid bar)
        numbers = dict(meaning.numbers)
        spindle = self.spindle is not None and meaning.drives_spindle
        bores = [o.start[1] for o in meaning.outlines if o.inside]
        if bores:
            why = ""
            if len(bores) < len(meaning.outlines):
                why = ("the program has both inside and outside G71/G70 profiles: the part check judges one "
                       "kind at a time")
            # the drilled hole is where the bore's cycle starts: the G71/G70 start point's X (Fanuc's form --
            # the boring bar enters the hole at its radius and roughs outward from it)
            elif min(bores) <= 0.0:
                why = (f"the bore's cycle starts at X {min(bores):g} (radius): no drilled hole to bore from "
                       "(the start point's X is the hole's)")
            else:
                hole = min(bores)
            if why:
                return Setup(MaterialRemoval(box(face - length, 0.0, face, radius), lathe_tool(0.0)), None,
                             Polygon(), [], why, spindle_checked=spindle, numbers=numbers)
        inside = hole > 0.0
        stock = box(face - length, hole, face, radius)
        if inside:
            # a boring bar lies in the hole, along the axis: it may reach below the axis; what it must not do is
            # reach through the hole into the wall on the far side (the tube below -hole in the full section)
            forbidden = [Forbidden("boring bar into the far wall of the bore", box(face - length, -FAR, face, -hole),
                                   across_axis=True)]
        else:
            forbidden = [Forbidden("tool across the spindle axis", box(-FAR, -FAR, FAR, 0.0), across_axis=True)]
        if self.limiter is not None and self.limiter in parameters:
            lower = -FAR
            for ref_max, lim_min, _lim_max in table_of(parameters[self.limiter]):
                top = min(ref_max, FAR)
                if abs(lim_min) < POSITION_LIMIT and top > lower:
                    forbidden.append(Forbidden("tool into the chuck jaws", box(lower, -1.0, top, lim_min)))
                lower = top
        cutters = lathe_cutters(meaning, self.settings, hole)
        default = cutters.pop(0)
        removal = MaterialRemoval(stock, default.outline, forbidden, default.max_depth, cutters)
        anchor = box(face - length, hole, face - length + min(1.0, length), radius)
        if meaning.programmed and not meaning.regions and self.settings.drawing is None:
            return Setup(removal, None, anchor, [], "the program has no G71/G70 profile to judge against",
                         spindle_checked=spindle, numbers=numbers)
        programmed, lines = programmed_part(stock, meaning)
        if self.settings.drawing is not None:
            from .drawing import lathe_part
            programmed = lathe_part(self.settings.drawing, stock)
            if meaning.programmed and not lines:     # no region: where the part is off, the nearest cut's line
                lines = _element_lines(p for p in meaning.elements if not p.rapid)
        return Setup(removal, programmed, anchor, lines, spindle_checked=spindle, numbers=numbers)


def lathe_cutters(meaning: ProgramMeaning, settings: PartSettings, hole: float = 0.0) -> dict[int, Cutter]:
    """The tools a lathe run sweeps, by turret station (the sequencer's ``tool`` output; 0: before any T word, and
    the registers' cycles): each the shape of the tool table's row the program's T words give it (the configured
    sequencer's ``meaning.tools``: ``T0102`` is station 1 with the row of offset 2 -- a station given several rows
    keeps the first; station 0, the row 0: no offset, a turning insert), placed at the axes' position less that
    row's offsets.

    A row is a drill (``drill_diameter`` > 0: :func:`~ncfmu.machining.drill`), a grooving or parting blade
    (``width`` > 0: :func:`~ncfmu.machining.grooving_insert`) or else a turning insert of ``insert_angle``
    (:func:`~ncfmu.machining.turning_insert`), with the row's nose radius (``settings.nose_radius`` when given:
    every tool's) placed as its imaginary tip says (``tip``; 0 and 9 -- the nose centre programmed -- as 3, an
    OD tool cutting toward the chuck, and in a bore of radius ``hole`` as 2, the boring bar: its body a
    hole's radius high); max_depth the row's (``settings.max_depth`` when given), 0 none. The axes stand at the
    programmed point plus the row's offsets and the program's first work offset (a program that changes its work
    offset is judged with its first)."""
    work = np.array(meaning.first_work if meaning.programmed else (0.0, 0.0))
    blade = hole if hole > 0.0 else BLADE
    cutters: dict[int, Cutter] = {}
    for use in meaning.tools:
        row = use.tool
        nose = row.nose_radius if settings.nose_radius is None else settings.nose_radius
        depth = row.max_depth if settings.max_depth is None else settings.max_depth
        tip = row.tip
        if tip in (0, 9):
            tip = 2 if hole > 0.0 else 3
        if row.drill_diameter > 0.0:
            outline, on_axis = drill(row.drill_diameter, DRILL_POINT), True
        else:
            shape = (grooving_insert(row.width, nose, blade) if row.width > 0.0
                     else turning_insert(nose, row.insert_angle, blade))
            outline, on_axis = placed(shape, tip, nose), False
        shift = np.array([row.z_offset, row.x_offset]) + work
        cutters[use.station] = Cutter(outline - shift, depth if depth > 0 else math.inf, on_axis)
    return cutters


def programmed_part(stock: Any, meaning: ProgramMeaning) -> tuple[Any, list[tuple[Any, int]]]:
    """The programmed part, the one place it is made (a drawing may stand in for it): the ``stock`` (a polygon:
    the lathe's half-section, the mill's plate) less the union of the regions the program's operations cut away
    by their definition (``meaning.regions``: G71/G70's all above a profile, a bore's all below it down to the
    hole, the registers' all above each block's deepest pass, every cycle's with a ``removed()``); and the
    programmed elements with their program lines (for naming the line nearest to a deviation: a profile's
    blocks, else the region's outline by its operation's line; the registers' none)."""
    import shapely
    from shapely.geometry import LineString, Polygon

    removed = [Polygon(r.outline).buffer(0) for r in meaning.regions]
    lines: list[tuple[Any, int]] = []
    for r in meaning.regions:
        if r.edges:
            lines += _element_lines(r.edges)
        elif r.line:
            lines.append((LineString(r.outline), r.line))
    return stock.difference(shapely.union_all(removed)), lines


def _element_lines(elements: Iterable[Programmed]) -> list[tuple[Any, int]]:
    """Each programmed element as a polyline, with its program line."""
    from shapely.geometry import LineString
    return [(LineString(_elements_polyline([p.element])), p.line) for p in elements]


@dataclass(frozen=True)
class MillPart(MachinedPart):
    """A ContourInterpolator milling along a closed contour with the axes ``x`` and ``y``: the contour is the
    part's outline -- the part inside it (milled around), or with ``contour.pocket`` the plate around it (a
    pocket's wall, milled from inside); the cutter's radius is the compensation's. A compensation to the side
    that puts the cutter into the part is a gouge; a corner of the pocket the round cutter cannot reach is
    material left. Nothing turns the work here (the mill system has no spindle drive): no spindle rule."""

    contour: str
    x: str
    y: str
    settings: PartSettings = PartSettings()
    axes: tuple[str, str] = ("X", "Y")

    def variables(self) -> tuple[str, ...]:
        return (*(f"{self.contour}.{v}" for v in ("segment", "done")), f"{self.x}.pos", f"{self.y}.pos")

    def plane_columns(self) -> tuple[str, str]:
        return f"{self.x}.pos", f"{self.y}.pos"

    def line_column(self) -> str:
        return f"{self.contour}.segment"

    def done_column(self) -> str:
        return f"{self.contour}.done"

    def setup(self, parameters: Parameters) -> Setup:
        import shapely
        from shapely.geometry import Polygon, box

        from ..controllers.contour import ContourInterpolator
        meaning: ProgramMeaning = configured(ContourInterpolator, parameters.get(self.contour, {})).meaning
        margin = meaning.stock.margin
        cutter = mill_cutter(meaning.cutter_radius)
        rapid_lines = meaning.rapid_lines
        contour = meaning.outlines[0].elements if meaning.outlines else ()
        elements = [p.element for p in contour]
        outline = _elements_polyline(elements) if elements else []
        closed = len(outline) > 3 and math.dist(outline[0], outline[-1]) < 1e-6
        part = Polygon(outline).buffer(0) if closed else None
        if self.settings.drawing is not None:
            part = self.settings.drawing.outline
        if part is None or part.is_empty:
            xs = [p[0] for p in outline] or [meaning.start[0]]
            ys = [p[1] for p in outline] or [meaning.start[1]]
            plate = box(min(xs) - margin, min(ys) - margin, max(xs) + margin, max(ys) + margin)
            return Setup(MaterialRemoval(plate, cutter), None, plate, [], "the contour is not closed: no part outline",
                         rapid_lines, numbers=dict(meaning.numbers))
        x0, y0, x1, y1 = part.bounds
        plate = box(x0 - margin, y0 - margin, x1 + margin, y1 + margin)
        lines = _element_lines(contour)
        if meaning.pocket:
            # a pocket: the part is the plate around the contour; the cutter must stay inside the contour (what
            # it must not enter reaches far beyond the plate, so the plate's own edge is no wall of it)
            wall = box(x0 - FAR, y0 - FAR, x1 + FAR, y1 + FAR).difference(part)
            part = plate.difference(part)
        else:
            wall = part
        gouge = Forbidden("cutter into the part's finished contour (gouge)", wall, self.settings.tolerance)
        shapely.prepare(part)
        return Setup(MaterialRemoval(plate, cutter, [gouge]), part, part, lines, "", rapid_lines,
                     numbers=dict(meaning.numbers))


def with_part_settings(report: Report, settings: PartSettings) -> Report:
    """``report`` with its part check judging by ``settings``."""
    parts = tuple(replace(p, settings=settings) if isinstance(p, (LathePart, MillPart, GrindPart)) else p
                  for p in report.parts)
    return replace(report, parts=parts)


def without_part_check(report: Report) -> Report:
    """``report`` without its part check (``--no-part-check``; the benchmark's other side)."""
    return replace(report, parts=tuple(p for p in report.parts if not isinstance(p, PartCheck)))


def part_check_only(report: Report) -> Report | None:
    """``report`` with its part check alone (what a live server feeds to publish crashes); None: it has none."""
    parts = tuple(p for p in report.parts if isinstance(p, PartCheck))
    return replace(report, parts=parts) if parts else None


def verdict_of(accumulator: ReportAccumulator) -> PartVerdict | None:
    """The part check's verdict of a run summarised as it went (None: the report has no part check)."""
    for acc in accumulator.parts:
        if isinstance(acc, _Judging):
            return acc.verdict()
    return None


def crashes_so_far(accumulator: ReportAccumulator) -> list[Crash]:
    """The crashes a run fed to ``accumulator`` has had up to its last row, without judging the part: what a
    live server publishes as they happen (``ncfmu serve``'s crash node and event read this after every chunk;
    the list only grows, up to the engine's MAX_CRASHES records)."""
    for acc in accumulator.parts:
        if isinstance(acc, _PartCheckAccumulator):
            return list(acc.setup.removal.crashes)
    return []


def verdict_of_result(report: Report, result, parameters: Parameters) -> PartVerdict | None:
    """The part check's verdict of a whole in-memory run."""
    if not any(isinstance(p, PartCheck) for p in report.parts) or not len(result.data):
        return None
    acc = report.accumulator(parameters)
    acc.open(columns_of(result.data))
    acc.write(result.data)
    acc.close(True, float(result.time[-1]))
    return verdict_of(acc)


# -- the grinder ---------------------------------------------------------------------------------------------
#: How many cycles' records a grinder's verdict keeps (the count, the worst and the verdict go on).
MAX_CYCLES = 1000


@dataclass(frozen=True)
class Spark:
    """Where a grinding program's size is made: the normal cycle's spark-out (the dwell at its deepest
    infeed), its address, the X it is programmed at (the feed origin plus the counted infeed) and the infeed's
    direction (+1: X grows into the work, as the seed's)."""

    address: int
    x: float
    sign: int


def spark_of(values: Parameters | dict) -> Spark | str:
    """The spark-out of a ProgrammableFeed's normal cycle (from ``start_address``), or why there is none: the
    program's words walked with the return counter (feeds counted, S4 wear feeds not, S1 back to 0); the first
    dwell where |counter| is at its largest is the spark-out."""
    from ..controllers.feed import ProgrammableFeed, parse_program
    v = {**ProgrammableFeed.default_parameters(), **values}
    try:
        program = parse_program(str(v["program"]))
    except Exception as err:          # the run refuses it, naming the line; nothing to judge here
        return f"the program does not read: {err}"
    d = [to_float(v[f"D{k}"]) for k in range(1, 8)]
    pc, counter, best = to_int(v["start_address"]), 0.0, None
    for _ in range(len(program) + 1):
        word = program.get(pc)
        if word is None or word.kind == "end":
            break
        if word.axis == "x" and word.kind == "feed" and not word.wear:
            counter += word.sign * d[word.d - 1]
        elif word.axis == "x" and word.kind == "return":
            counter = 0.0
        elif word.kind == "dwell" and (best is None or abs(counter) > abs(best[1]) + 1e-12):
            best = (pc, counter)
        pc += 1
    if best is None or best[1] == 0.0:
        return "the normal cycle has no spark-out (a dwell T after an infeed of X) to measure the size at"
    return Spark(best[0], to_float(v["x_origin"]) + best[1], 1 if best[1] > 0 else -1)


@dataclass
class GrindVerdict(PartVerdict):
    """A grinder's parts, one a cycle: each cycle's size against the programmed X of its spark-out.

    A cycle's **size** is the deepest actual X the wheel reached from the cycle's START to the end of its
    spark-out, less the wheel-wear compensation made so far: grinding only removes, so the work is as small as
    the wheel's deepest reach left it (an overshoot of the fine feed grinds deeper than where the axis settles;
    a wheel still short of its command when the spark-out ends leaves that much on); a wear compensation
    (START2's S4 feed) moves the feed origin by what the wheel wore, so the wheel's face -- the part's size --
    stands that much short of the axis. The error is along the infeed: > 0 too deep (``max_gouge_mm``, the part
    undersize on the radius), < 0 short (``max_left_mm``, stock left). A cycle that ends before its spark-out
    does (EMB, an alarm) made no part and is counted as aborted."""

    programmed_x_mm: float = math.nan
    cycles: list[dict[str, float]] = field(default_factory=list)
    cycle_count: int = 0
    aborted: int = 0
    worst_error_mm: float = math.nan
    worst_cycle: int = 0

    def as_json(self) -> dict[str, object]:
        out = super().as_json()
        for key in ("left_at", "gouge_at"):
            out.pop(key, None)
        out.update({"programmed_x_mm": self.programmed_x_mm, "cycles_judged": self.cycle_count,
                    "cycles_aborted": self.aborted,
                    "worst_error_mm": None if math.isnan(self.worst_error_mm) else self.worst_error_mm,
                    "worst_cycle": self.worst_cycle or None, "cycles": self.cycles,
                    "cycles_kept": len(self.cycles)})
        return out

    def summary(self) -> list[str]:
        tol = f"{self.tolerance_mm:.4f} mm"
        if self.judged:
            return [f"  part: not judged: {self.judged}"]
        head = (f"  part: {self.cycle_count} cycle{'s' if self.cycle_count != 1 else ''} judged"
                + (f" ({self.aborted} aborted)" if self.aborted else "")
                + f", size vs the programmed X {self.programmed_x_mm:.4f} mm: worst {self.worst_error_mm:+.4f} mm "
                  f"(cycle {self.worst_cycle})")
        if self.within_tolerance:
            return [f"{head}, within {tol}"]
        out = [c for c in self.cycles if abs(c["error_mm"]) > self.tolerance_mm]
        lines = [f"{head}: OUT OF TOLERANCE {tol} in {sum(1 for _ in out)} of the cycles kept"]
        lines += [f"  part: cycle {c['cycle']:.0f} at t = {c['t']:.3f} s: size {c['size_mm']:.4f} mm, error "
                  f"{c['error_mm']:+.4f} mm" for c in out[:CRASH_LINES]]
        return lines

    def metrics(self) -> dict[str, float]:
        return {**super().metrics(), "worst_size_error_mm": self.worst_error_mm}


@dataclass(frozen=True)
class GrindPart(PartCheck):
    """A ProgrammableFeed grinding with its infeed axis ``x``: each cycle's size (:class:`GrindVerdict`)."""

    feed: str
    x: str
    settings: PartSettings = PartSettings()

    def variables(self) -> tuple[str, ...]:
        return (*(f"{self.feed}.{v}" for v in ("pc", "run", "x_cmd", "return_counter_x")), f"{self.x}.pos")

    def accumulator(self, parameters: Parameters) -> PartAccumulator:
        return _GrindAccumulator(self, parameters)


class _GrindAccumulator(_Judging):
    """Follows the cycles as the rows come: a part starts at RUN's rising edge (not at the wear address); its
    deepest actual X is kept until the program counter leaves the spark-out for the word after it -- the size
    is taken there, with the wear so far (the feed origin's shift: X command less return counter less
    x_origin)."""

    part: GrindPart

    def __init__(self, part: GrindPart, parameters: Parameters) -> None:
        super().__init__(part)
        from ..controllers.feed import ProgrammableFeed
        values = {**ProgrammableFeed.default_parameters(), **parameters.get(part.feed, {})}
        self.spark = spark_of(values)
        self.wear_address = to_int(values["wear_address"])
        self.origin = to_float(values["x_origin"])
        self.tol = part.settings.tolerance
        self.in_part = False
        self.deepest = -math.inf             # sign * X, the deepest of the present part
        self._prev: tuple[int, bool] | None = None       # the last row's pc and RUN
        self._last_row = (math.nan, math.nan, math.nan)   # and its time, X command, return counter
        self.cycles: list[dict[str, float]] = []
        self.count = self.aborted = 0
        self.worst, self.worst_cycle = math.nan, 0
        self.max_left = self.max_gouge = 0.0

    def write(self, rows: np.ndarray) -> None:
        super().write(rows)
        if not isinstance(self.spark, Spark):
            return
        p, sp = self.part, self.spark
        pc = rows[f"{p.feed}.pc"].astype(np.int64)
        run = rows[f"{p.feed}.run"].astype(bool)
        depth = sp.sign * rows[f"{p.x}.pos"]
        t, cmd, counter = rows["time"], rows[f"{p.feed}.x_cmd"], rows[f"{p.feed}.return_counter_x"]
        prev_pc, prev_run = self._prev if self._prev is not None else (int(pc[0]), False)
        before_pc = np.concatenate(([prev_pc], pc[:-1]))
        before_run = np.concatenate(([prev_run], run[:-1]))
        starts = np.flatnonzero(run & ~before_run)
        stops = np.flatnonzero(~run & before_run)
        ends = np.flatnonzero((before_pc == sp.address) & (pc != sp.address))
        events = sorted([(int(i), 0) for i in starts] + [(int(i), 1) for i in ends] + [(int(i), 2) for i in stops])
        a = 0
        for i, kind in events:
            if self.in_part and i > a:
                self.deepest = max(self.deepest, float(depth[a:i].max()))
            a = i
            if kind == 0:
                self.in_part = int(pc[i]) != self.wear_address
                self.deepest = -math.inf
            elif kind == 1 and self.in_part:
                # the spark-out's last row: the row before (the chunk before's last, at a chunk's first row)
                at = self._last_row if i == 0 else (float(t[i - 1]), float(cmd[i - 1]), float(counter[i - 1]))
                self._measure(*at, normal=bool(run[i]) and int(pc[i]) == sp.address + 1)
            elif kind == 2 and self.in_part:
                self.aborted += 1               # RUN ended before the spark-out did (EMB, an alarm)
                self.in_part = False
        if self.in_part and a < len(rows):
            self.deepest = max(self.deepest, float(depth[a:].max()))
        self._prev = (int(pc[-1]), bool(run[-1]))
        self._last_row = (float(t[-1]), float(cmd[-1]), float(counter[-1]))

    def _measure(self, t: float, cmd: float, counter: float, normal: bool) -> None:
        """The part of the cycle whose spark-out ended at the row at ``t`` with the X command ``cmd`` and return
        counter ``counter`` (the word after the spark-out follows when ``normal``)."""
        self.in_part = False
        if not normal:
            self.aborted += 1
            return
        sp = self.spark
        assert isinstance(sp, Spark)
        wear = cmd - counter - self.origin
        reached = sp.sign * self.deepest
        size = reached - wear
        error = sp.sign * (size - sp.x)
        self.count += 1
        if math.isnan(self.worst) or abs(error) > abs(self.worst):
            self.worst, self.worst_cycle = error, self.count
        self.max_left, self.max_gouge = max(self.max_left, -error), max(self.max_gouge, error)
        if len(self.cycles) < MAX_CYCLES:
            self.cycles.append({"cycle": self.count, "t": t, "x_deepest_mm": reached,
                                "wear_mm": wear, "size_mm": size, "error_mm": error})

    def verdict(self) -> PartVerdict:
        why = self.spark if isinstance(self.spark, str) else ""
        if not why and not self.count:
            why = "no grinding cycle finished its spark-out" + (f" ({self.aborted} aborted)" if self.aborted else "")
        x = self.spark.x if isinstance(self.spark, Spark) else math.nan
        return GrindVerdict([], 0, self.tol, why, max_left_mm=self.max_left if self.count else math.nan,
                            max_gouge_mm=self.max_gouge if self.count else math.nan, axes=("X", "X"),
                            programmed_x_mm=x, cycles=list(self.cycles), cycle_count=self.count,
                            aborted=self.aborted, worst_error_mm=self.worst, worst_cycle=self.worst_cycle)


def check_drawing_for(report: Report, drawing: Any) -> None:
    """Refuse, before anything runs, a drawing (a :class:`~.drawing.Drawing`) the ``report``'s part check cannot
    take: a lathe's below the axis."""
    from .drawing import half_section
    if any(isinstance(p, LathePart) for p in report.parts):
        half_section(drawing)
