"""Contour interpolator with cutter compensation (seed: GB 1,175,423, Cincinnati Milling).

The contour comes as a part program (``program``, an RS274/NGC subset: :mod:`.rs274`) or, when
``program`` is empty, as the seed's terminal points ``point[i]`` (the nominal cutter-centre path,
offset by ``r = side * diameter_delta / 2``, left of travel for ``side = +1``). Both become one
representation inside -- a chain of lines and arcs -- compensated by one function
(:func:`.geometry.compensate`) and run by one interpolator.

Compensation: the seed's offset-segment intersection at corners between lines that turn by at most
90 degrees (the corner moves at most ``r*sqrt(2)``); an arc of radius ``r`` around every other outside
corner; inside corners trimmed to the intersection of the offsets, and an alarm naming the segment
(or program line) where the cutter does not fit. A program's G41/G42 starts with a straight lead-in
to the offset start of the contour, G40 ends with a straight lead-out (LinuxCNC, Fanuc type A).

Interpolation: on lines, as the seed, a DDA per axis (iterative additions with carry, computed in
closed form -- after k of N = 2^bits iterations an axis with span |d| has emitted
floor((N/2 + k*|d|) / N) pulses) moves all axes at once in units of ``dda_unit``; on arcs, the exact
point on the circle at the path length reached, rounded to whole ``dda_unit`` per axis (each axis still
moves in whole increments; the command is within half an increment per axis of the circle). The
vector feed is constant: the path length advances at the feed.

Path planning (the speed along the path): exact stop at every corner, i.e. the speed comes to 0
wherever the direction is not continuous, so no axis is asked for a velocity step; speed carries
through tangent junctions. On a path of lines the path acceleration is ``accel``; on a path with arcs
the tangential acceleration is held to 0.8 ``accel`` and the speed on an arc of radius R to
sqrt(0.55 ``accel`` R), so the vector acceleration (tangential and centripetal) stays below ``accel``
(0.975 ``accel``). A look-ahead (computed once, backwards from every exact stop) brings the speed down in
time. ``feed * feed_override`` (0..1.5) and feed hold act online within the same limits.
A bad input (NaN, a position beyond any machine, a position jump no axis can make) raises the alarm
and brings the path to a controlled stop along the contour; an override outside 0..1.5 is clamped and
said once.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

from ..errors import ConfigError, ProgramError, require
from ..ports import boolean, integer, real, string
from . import rs274
from .base import POSITION_LIMIT, as_float, int_param, real_param, servo_ports
from .cycle import CycleController, cycle_ports
from .geometry import TANGENT, Arc, CornerError, Element, Line, ToolMove, compensate, turn_angle
from .meaning import ProgramMeaning, mill_meaning, points_meaning
from .motion import stop_speed
from .mypyc_compat import mypyc_attr

MAX_POINTS = 64
#: The point path of the FMU's start values: one 10 mm move along X (a system gives its own).
DEFAULT_PATH = ((0.0, 0.0), (10.0, 0.0))
#: On a path with arcs: tangential acceleration and centripetal acceleration, as fractions of ``accel``
#: (sqrt(0.8**2 + 0.55**2) = 0.97 < 1, room for the discrete steps).
ARC_TANGENTIAL = 0.8
#: No cutter differs from its nominal diameter by more than this (mm).
MAX_DIAMETER_DELTA = 100.0
ARC_CENTRIPETAL = 0.55


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
class GeometryError(ConfigError):
    """The corrected path cannot be built (a gouging inside corner, an element that vanishes or reverses)."""


def point_contour(points: Sequence[tuple[float, float]], closed: bool) -> list[Line]:
    """The lines through ``points`` (back to the first for a ``closed`` path)."""
    pts = [(float(x), float(y)) for x, y in points]
    if closed and len(pts) > 2 and pts[0] == pts[-1]:
        pts = pts[:-1]
    lines = [Line(a, b) for a, b in zip(pts, pts[1:])]
    if closed:
        lines.append(Line(pts[-1], pts[0]))
    return lines


def program_path(moves: Sequence[rs274.Move], r: float, rapid_feed: float) -> list[ToolMove]:
    """The cutter-centre path of a parsed program; G41 offsets by ``+r``, G42 by ``-r``.

    Raises
    ------
    ProgramError
        naming the program line where compensation is impossible.
    """
    out: list[ToolMove] = []
    i = 0
    while i < len(moves):
        m = moves[i]
        if m.comp_before == m.comp_after == 0:
            out.append(ToolMove(m.element, m.rapid, rapid_feed if m.rapid else m.feed, m.line))
            i += 1
            continue
        # lead-in m, the contour moves[i+1 .. j-1], lead-out moves[j] (the parser guarantees one)
        j = i + 1
        while moves[j].comp_after != 0:
            j += 1
        chain, lead_out = moves[i + 1:j], moves[j]
        d = m.comp_after * r
        # a contour that returns to its start is joined there too (the lead-in and the lead-out meet at the
        # joined corner), so entering a closed contour at a corner leaves no cusp and does not gouge
        closed = len(chain) > 1 and math.dist(chain[0].element.start, chain[-1].element.end) < 1e-9
        try:
            pieces = compensate([c.element for c in chain], d, closed=closed)
        except CornerError as err:
            bad = chain[err.index]
            code = "G41" if m.comp_after > 0 else "G42"
            reason = err.describe([f"the block on line {c.line}" for c in chain])
            raise ProgramError(bad.line, 1, f"line {bad.line}",
                               f"cutter compensation ({code}, r = {r:g} mm): {reason}") from None
        entry = pieces[0][0].start if pieces else m.element.offset(d).end
        exit_ = pieces[-1][0].end if pieces else entry
        out.append(ToolMove(Line(m.element.start, entry), m.rapid, rapid_feed if m.rapid else m.feed, m.line))
        for element, k in pieces:
            c = chain[k]
            out.append(ToolMove(element, c.rapid, rapid_feed if c.rapid else c.feed, c.line))
        out.append(ToolMove(Line(exit_, lead_out.element.end), lead_out.rapid,
                            rapid_feed if lead_out.rapid else lead_out.feed, lead_out.line))
        i = j + 1
    return [t for t in out if t.element.length > 0.0]


def _point_ports():
    ports = []
    for i in range(1, MAX_POINTS + 1):
        x, y = DEFAULT_PATH[i - 1] if i <= len(DEFAULT_PATH) else (0.0, 0.0)
        ports += [real(f"point[{i}].x", "parameter", x, "mm", f"terminal point {i}: X", min=-POSITION_LIMIT,
                       max=POSITION_LIMIT),
                  real(f"point[{i}].y", "parameter", y, "mm", f"terminal point {i}: Y", min=-POSITION_LIMIT,
                       max=POSITION_LIMIT)]
    return tuple(ports)


@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)
class ContourInterpolator(CycleController):
    MODEL_NAME = "ContourInterpolator"
    DESCRIPTION = ("Contour interpolator with cutter compensation: part programs (RS274 subset) or terminal points, "
                   "lines and arcs, offset corners, DDA interpolation, exact stop, feed override (GB 1,175,423)")
    SEED = "cutter-compensation-GB1175423.txt"
    STOP_TIME = 40.0
    AXES = ("x", "y")
    #: Rebuilt from the parameters, not saved with a state (fmi/state.py): what the program means.
    DERIVED: ClassVar[tuple[str, ...]] = (*CycleController.DERIVED, "meaning")

    PORTS = (
        string("program", "parameter", "", "part program, RS274/NGC subset (G00-G03 with I/J, G17, G21, G90/G91, "
               "G40-G42, F mm/min, M02/M30), one block per line; empty: the point path"),
        integer("n_points", "parameter", len(DEFAULT_PATH), "point path: number of terminal points",
                min=2, max=MAX_POINTS),
        *_point_ports(),
        boolean("closed", "parameter", False, "point path: closes from the last point back to the first"),
        real("diameter_delta", "parameter", 0.0, "mm", "actual minus nominal cutter diameter (the offset is half)",
             min=-MAX_DIAMETER_DELTA, max=MAX_DIAMETER_DELTA),
        integer("side", "parameter", -1, "point path: side of the correction, +1 left of travel, -1 right "
                "(a program chooses with G41/G42)", min=-1, max=1, allowed=(-1, 1)),
        real("feed", "parameter", 5.0, "mm/s", "point path: vector feed rate (a program gives F)", min=0.0,
             min_exclusive=True),
        real("approach_feed", "parameter", 5.0, "mm/s", "vector feed of the approach (segment 0) and of G00 moves",
             min=0.0, min_exclusive=True),
        real("accel", "parameter", 500.0, "mm/s2", "path acceleration limit (start, stop, corners, arcs, "
             "override, hold)", min=0.0, min_exclusive=True),
        *cycle_ports("the contour", "inpos_timeout"),
        real("dda_unit", "parameter", 0.001, "mm", "DDA output increment (one pulse)", min=1e-6, max=1.0),
        real("x_start", "parameter", 0.0, "mm", "X command before the cycle (the axis's start position; a "
             "program starts here)", min=-POSITION_LIMIT, max=POSITION_LIMIT),
        real("y_start", "parameter", -10.0, "mm", "Y command before the cycle (the axis's start position; a "
             "program starts here)", min=-POSITION_LIMIT, max=POSITION_LIMIT),
        boolean("start", "input", False, "cycle start (rising edge)"),
        boolean("feed_hold", "input", False, "feed hold: decelerate and stop on the path while true"),
        real("feed_override", "input", 1.0, "1", "feed override", min=0.0, max=1.5),
        *servo_ports(("x", 0.0), ("y", 0.0)),
        integer("segment", "output", None, "point path: segment being interpolated; program: line of the block "
                "(0: the approach from where the tool stands to the path's start)"),
        boolean("busy", "output", None, "a contour is running"),
        boolean("done", "output", None, "the contour is finished (until the next start)"),
        boolean("alarm", "output", None, "geometry cannot be corrected, or a bad input"),
        # appended: the ports before keep their value references
        *cycle_ports("the contour", "max_following_error", "inpos_band"),
        # appended: the plate the part check cuts (read by the host's part check, not by the interpolator)
        real("stock_margin", "parameter", 5.0, "mm", "the plate stock: the contour's bounding box grown by this "
             "much on every side (the part check's material; the interpolator does not read it)", min=0.0,
             max=POSITION_LIMIT),
        # appended: which side of the closed contour the part is (the part check's; the interpolator does not read it)
        boolean("pocket", "parameter", False, "the part check's part: false, the part is inside the closed "
                "contour (milled around); true, the part is the plate around it (a pocket, the cutter starting "
                "inside it)"),
    )

    #: What only the point path reads: a program replaces it (its own G41/G42, F and path).
    POINT_PATH_ONLY: ClassVar[tuple[str, ...]] = ("n_points", "closed", "side", "feed")

    @classmethod
    def unread(cls, values: Mapping[str, object]) -> dict[str, str]:
        out = super().unread(values)
        if str(values.get("program", "")).strip():
            for p in cls.ports("parameter"):
                if p.name.startswith("point[") or p.name in cls.POINT_PATH_ONLY:
                    out[p.name] = "runs its program (program is set), not the point path"
        return out

    def configure(self, values: Mapping[str, object]) -> None:
        self.program = str(values["program"])
        self.closed = bool(values["closed"])
        self.diameter_delta = real_param(values, "diameter_delta")
        self.side = int_param(values, "side")
        self.feed = real_param(values, "feed")
        self.approach_feed = real_param(values, "approach_feed")
        self.accel = real_param(values, "accel")
        self.configure_cycle(values)
        self.dda_unit = real_param(values, "dda_unit")
        self.x_start = real_param(values, "x_start")
        self.y_start = real_param(values, "y_start")
        self.geometry_error: str | None = None
        # the part check's: the interpolator publishes them with the program's meaning, it does not read them
        cutter, margin = abs(self.diameter_delta) / 2.0, real_param(values, "stock_margin")
        pocket = bool(values["pocket"])
        if self.program.strip():
            moves = rs274.parse(self.program, (self.x_start, self.y_start))
            self.contour: list[Element] = [m.element for m in moves]
            self.meaning: ProgramMeaning = mill_meaning(moves, rs274.read(self.program, rs274.MILL),
                                                        (self.x_start, self.y_start), cutter, margin, pocket)
            try:
                path = program_path(moves, self.diameter_delta / 2.0, self.approach_feed)
            except ProgramError as err:
                path, self.geometry_error = [], str(err)
        else:
            n = int_param(values, "n_points")
            pts = [(real_param(values, f"point[{i}].x"),
                    real_param(values, f"point[{i}].y"))
                   for i in range(1, n + 1)]
            for i in range(1, n):
                require(pts[i] != pts[i - 1], f"point[{i + 1}]", pts[i], f"repeats point[{i}]: consecutive points "
                                                                         "must differ")
            if self.closed and pts[0] == pts[-1]:
                require(n >= 4, "n_points", n, "a closed path needs at least 3 distinct points")
            self.points = pts
            self.contour = list[Element](point_contour(pts, self.closed))
            self.meaning = points_meaning(self.contour, (self.x_start, self.y_start), cutter, margin, pocket)
            try:
                pieces = compensate(self.contour, self.side * self.diameter_delta / 2.0, self.closed)
                path = [ToolMove(e, False, self.feed, k + 1) for e, k in pieces]
            except CornerError as err:
                k = err.index
                reason = err.describe([f"segment {j + 1}" for j in range(len(self.contour))])
                path, self.geometry_error = [], str(GeometryError(
                    f"point[{k + 1}]", self.points[k], f"segment {k + 1} (point[{k + 1}] -> "
                    f"point[{(k + 1) % len(self.points) + 1}]): {reason}"))
        self.tool_path: list[ToolMove] = path
        has_arcs = any(isinstance(t.element, Arc) for t in path)
        self.path_accel = self.accel * (ARC_TANGENTIAL if has_arcs else 1.0)
        self._caps = [math.sqrt(ARC_CENTRIPETAL * self.accel * t.element.radius)
                      if isinstance(t.element, Arc) else math.inf for t in path]

    def _plan(self, path: Sequence[ToolMove], caps: Sequence[float], scale: float | None) -> list[float]:
        """Highest speed at the end of each move, backwards: 0 at a corner (exact stop) and at the end; through a
        tangent junction, what the following moves allow -- their arc caps and exact stops (``scale`` None: the
        hard limits, independent of the override) and also their feeds times ``scale`` (the soft limits)."""
        v_end = [0.0] * len(path)
        for k in range(len(path) - 2, -1, -1):
            a, b = path[k].element, path[k + 1].element
            if abs(turn_angle(a.tangent(a.length), b.tangent(0.0))) > 1e3 * TANGENT:
                continue
            entry_next = math.sqrt(v_end[k + 1] ** 2 + 2.0 * self.path_accel * b.length)
            v_end[k] = min(caps[k], caps[k + 1], entry_next)
            if scale is not None:
                v_end[k] = min(v_end[k], path[k + 1].feed * scale)
        return v_end

    def reset(self) -> None:
        self.cmd = [self.x_start, self.y_start]
        self.vff = [0.0, 0.0]
        self.segment = 0
        self.busy = False
        self.done = False
        self.reset_cycle()
        self.alarm = self.geometry_error is not None
        if self.alarm:
            self.say("error", f"cutter compensation impossible: {self.geometry_error}")
        self.v = 0.0                      # path speed, mm/s
        self._run: list[ToolMove] = []    # the moves of the running cycle (the approach, then the tool path)
        self._v_end_hard: list[float] = []  # per move of the cycle: its end speed limit, hard and at the override
        self._v_end_soft: list[float] = []
        self._plan_scale = 1.0
        self._caps_run: list[float] = []
        self._i = 0                       # index of the move being run; len(_run): the path is finished
        self._s = 0.0                     # path length done within it, mm
        self._dda: tuple[tuple[int, int], tuple[int, int], int] | None = None
        self._halting = False             # controlled stop after an alarm
        self._outputs: dict[str, object] = {}
        self._publish()

    # -- starting a cycle ---------------------------------------------------------------------------
    def _begin_cycle(self) -> None:
        here = (self.cmd[0], self.cmd[1])
        first = self.tool_path[0].element.start
        approach = []
        if math.hypot(first[0] - here[0], first[1] - here[1]) > 0.5 * self.dda_unit:
            approach = [ToolMove(Line(here, first), True, self.approach_feed, 0)]
        self._run = approach + self.tool_path
        self._caps_run = [math.inf] * len(approach) + self._caps
        self._v_end_hard = self._plan(self._run, self._caps_run, None)
        self._v_end_soft = self._plan(self._run, self._caps_run, self._plan_scale)
        self._i, self._s, self.v = 0, 0.0, 0.0
        self.inpos.reset()
        self._enter(0)

    def _enter(self, i: int) -> None:
        """Make move ``i`` the present one: the DDA of a line is loaded with its span in whole units."""
        self._i = i
        if i >= len(self._run):
            self._dda = None
            return
        move = self._run[i]
        self.segment = move.label
        if isinstance(move.element, Line):
            start = (self._counts(move.element.start[0]), self._counts(move.element.start[1]))
            span = (self._counts(move.element.end[0]) - start[0], self._counts(move.element.end[1]) - start[1])
            n_iter = 1 << max(1, max(abs(span[0]), abs(span[1]))).bit_length()    # normalised: MSB set
            self._dda = (start, span, n_iter)
        else:
            self._dda = None

    # -- positions: the DDA on lines, whole increments on arcs ------------------------------------------
    def _counts(self, value: float) -> int:
        return round(value / self.dda_unit)

    def _position(self) -> tuple[float, float]:
        move = self._run[self._i]
        if self._dda is None:                                      # an arc
            x, y = move.element.point(self._s)
            return self._counts(x) * self.dda_unit, self._counts(y) * self.dda_unit
        (sx, sy), (dx, dy), n = self._dda
        length = move.element.length
        k = n if self._s >= length else int(self._s / length * n)
        half = n >> 1                                              # accumulators preset to N/2: rounds the carries
        px = sx + (1 if dx >= 0 else -1) * ((half + k * abs(dx)) // n)
        py = sy + (1 if dy >= 0 else -1) * ((half + k * abs(dy)) // n)
        return px * self.dda_unit, py * self.dda_unit

    # -- the hooks of the NC cycle (controllers/cycle.py owns the order of a step) -----------------------
    ALARM_INPUT = ""                      # no external alarm input: nothing holds the mill's axes
    STOP_SAYS = "decelerating to rest on the path, cycle stopped"
    MOTION_SAYS = "the path is"

    def halt(self) -> None:
        """The path decelerates to rest along the contour (:meth:`advance`); the cycle ends."""
        self.busy = False
        self._halting = self._i < len(self._run) and self.v > 0.0

    def watching_following_error(self) -> bool:
        return self.busy                                # why: in CycleController

    def at_rest(self) -> bool:
        return not self._halting

    def command_point(self) -> list[float]:
        return self.cmd

    def rebase(self, actual: Mapping[str, float]) -> None:
        """The next cycle's approach starts where the tool stands."""
        self.cmd = [actual["x"], actual["y"]]

    def take_commands(self, t: float, inputs: Mapping[str, object], edges: Any, bad: str | None,
                      why: str | None) -> None:
        if not why:                                     # a step that raised the alarm takes no START
            super().take_commands(t, inputs, edges, bad, why)

    def start(self, t: float, inputs: Mapping[str, object], edges: Any) -> None:
        if self.geometry_error:                         # the alarm stays: the cutter does not fit
            self.say("error", f"t = {t:.4f} s: start refused: {self.geometry_error}")
            return
        super().start(t, inputs, edges)

    def begin(self, t: float, edges: Any) -> None:
        self.done, self.busy = False, True
        self._begin_cycle()

    def advance(self, t: float, dt: float, inputs: Mapping[str, object], why: str | None) -> None:
        if self._halting:
            self._advance(t, dt, 0.0, inputs, finishing=False)
            self._halting = self.v > 0.0
            if not self._halting:
                self.vff = [0.0, 0.0]
        elif why:
            self.vff = [0.0, 0.0]
        elif self.busy:
            scale = 0.0 if inputs["feed_hold"] else self.override.read(self, t, as_float(inputs["feed_override"]))
            self._advance(t, dt, scale, inputs)

    def _advance(self, t: float, dt: float, scale: float, inputs: Mapping[str, object],
                 finishing: bool = True) -> None:
        """Advance the path by one step at ``scale`` times the programmed feed (override; 0: hold or halt)."""
        if self._i < len(self._run):
            i = self._i
            move, length = self._run[i], self._run[i].element.length
            a = self.path_accel
            a_dt = a * dt
            v_old = self.v
            if scale > 0.0 and scale != self._plan_scale:          # the override moved: the feeds ahead did
                self._plan_scale = scale
                self._v_end_soft = self._plan(self._run, self._caps_run, scale)
            remaining = length - self._s
            hard, soft = self._v_end_hard[i], self._v_end_soft[i]
            v_stop = stop_speed(remaining + hard * hard / (2.0 * a), v_old, a, dt)
            # a lower feed ahead is reached in time, but never by braking harder than accel (after an override
            # drop the next block may begin above its new feed and slow down within it)
            v_feed = max(stop_speed(remaining + soft * soft / (2.0 * a), v_old, a, dt), v_old - a_dt)
            target = min(move.feed * scale, self._caps_run[i])
            v = max(min(min(max(target, v_old - a_dt), v_old + a_dt), v_stop, v_feed), 0.0)
            # in exact arithmetic v_stop >= v_old - a_dt (the last step braked in time); rounding must not make it
            # brake harder than accel
            v = max(v, v_old - a_dt)
            s = self._s + 0.5 * (v_old + v) * dt
            while True:
                length = self._run[self._i].element.length
                at_rest_short = v == 0.0 and length - s <= 1e-12
                if s < length and not at_rest_short:
                    break
                if self._v_end_hard[self._i] == 0.0 or self._i == len(self._run) - 1:
                    if self._i == i and v_old > a_dt:
                        # rounding in s left a speed above one step's braking: stand at the end and shed it at
                        # accel, so no axis is asked for more than accel even by the last digits
                        s, v = length, v_old - a_dt
                        break
                    s, v = 0.0, 0.0                             # exact stop at the corner (or the end)
                    self._enter(self._i + 1)
                    break
                s -= length                                     # tangent junction: the speed carries on
                self._enter(self._i + 1)
            self._s, self.v = s, v
            if self._i < len(self._run):
                self.cmd = list(self._position())
                tx, ty = self._run[self._i].element.tangent(self._s)
                self.vff = [v * tx, v * ty]
                return
            end = self._run[-1].element.end
            self.cmd = [self._counts(end[0]) * self.dda_unit, self._counts(end[1]) * self.dda_unit]
        self.vff = [0.0, 0.0]
        self.v = 0.0
        if not finishing:
            return
        if self.arrival(t, dt, True, inputs):
            self.busy, self.done = False, True

    def _publish(self) -> dict[str, object]:
        out = self._outputs
        out["x_cmd"], out["y_cmd"] = self.cmd
        out["x_vff"], out["y_vff"] = self.vff
        out["segment"] = self.segment
        out["busy"], out["done"], out["alarm"] = self.busy, self.done, self.alarm
        return out

    def check_state(self, inputs: Mapping[str, object]) -> str | None:
        """A restored state: the cycle's moves are the tool path (after at most an approach to its start), their
        plans and the DDA what they give, the command the point the path position gives."""
        why = super().check_state(inputs)
        if why:
            return why
        run, path = self._run, self.tool_path
        k = len(run) - len(path)
        if run and (k not in (0, 1) or run[k:] != path):
            return "_run: not the tool path (after at most an approach to its start)"
        if k == 1 and not (run[0].rapid and run[0].feed == self.approach_feed and run[0].label == 0
                           and isinstance(run[0].element, Line) and run[0].element.end == path[0].element.start
                           and all(abs(x) <= POSITION_LIMIT for x in run[0].element.start)):
            return f"_run[0] = {run[0]!r}: not an approach to the tool path's start"
        if not 0.0 < self._plan_scale <= 1.5:
            return f"_plan_scale = {self._plan_scale!r}: not a feed override in (0, 1.5]"
        if self._caps_run != ([math.inf] * k + self._caps if run else []):
            return "_caps_run: not the speed caps of the cycle's moves"
        planned = (self._plan(run, self._caps_run, None), self._plan(run, self._caps_run, self._plan_scale))
        if (self._v_end_hard, self._v_end_soft) != planned:
            return "_v_end_hard, _v_end_soft: not the plan of the cycle's moves"
        if not 0 <= self._i <= len(run):
            return f"_i = {self._i!r}: not a move of the cycle ({len(run)} moves)"
        segment, dda = self.segment, self._dda
        self._enter(self._i)                                          # the DDA (and the label) it loads
        if self._dda != dda or self.segment != segment:
            return f"_dda = {dda!r}, segment = {segment!r}: not what move {self._i} loads"
        top = max(self.feed, self.approach_feed) * 1.5
        if self._i < len(run) and not (0.0 <= self._s <= run[self._i].element.length and 0.0 <= self.v <= top):
            return f"_s = {self._s!r}, v = {self.v!r}: not within move {self._i}"
        if math.hypot(*self.vff) > self.v + 1e-9 and self.v <= top:
            return f"vff = {self.vff!r}: faster than the path speed v = {self.v!r}"
        if self._i < len(run):
            at = list(self._position())
        elif run:
            end = run[-1].element.end
            at = [self._counts(end[0]) * self.dda_unit, self._counts(end[1]) * self.dda_unit]
        else:
            at = [self.x_start, self.y_start]
        if self.cmd != at:
            return f"cmd = {self.cmd!r}: not the point of the path the state stands at ({at!r})"
        return self.outputs_fault()
