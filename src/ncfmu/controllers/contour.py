"""Contour interpolator with cutter compensation (seed: GB 1,175,423, Cincinnati Milling).

The programmed path is the nominal cutter-centre path (terminal points ``point[i]``). When the actual
cutter differs from the nominal one by ``diameter_delta``, the centre path moves sideways by the
correction ``r = diameter_delta / 2`` (to the left of travel for ``side = +1``, to the right for -1).

Compensation, as the seed: at every terminal point a compensation vector -- built from the unit
vectors of the two segments meeting there -- is scaled by the correction and added to the point,
giving the intersection of the two segments offset perpendicular by ``r``::

    C = P + r * (n1 + n2) / (1 + u1 . u2)        (u: unit directions, n: their left normals * side)

At the ends of an open path the point is offset along its one segment's normal. Reversing segments
(1 + u1.u2 ~ 0) and a correction that would make a corrected segment vanish or run backwards are
reported (alarm + message) and the cycle does not start -- never a silent loop.

Interpolation, as the seed: a DDA per axis (iterative additions with carry) moves all axes at once
from corrected point to corrected point in units of ``dda_unit``; the iteration rate goes with
1/segment length, so the vector feed is constant. It is computed in closed form -- after k iterations
an axis with span |d| over N = 2^bits iterations has emitted floor((N/2 + k*|d|) / N) pulses, exactly
what the iterative additions give. The path speed follows ``feed * feed_override`` (0..1.5) and feed
hold within ``accel``, so neither acts as a jump. Segment 0 is the approach from the present position
to the first corrected point.

A bad input (NaN, a position beyond any machine, a position jump no axis can make) raises the alarm
and brings the path to a controlled stop: it decelerates along the contour at ``accel`` and rests
there; an override outside 0..1.5 is clamped and said once.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from ..errors import ConfigError, require
from ..ports import boolean, integer, real
from .base import Controller, OverrideDial, PositionGuard, finite_inputs, int_param, real_param, servo_ports

MAX_POINTS = 64
#: The contour ends when the actual axes are this close to its last command (mm).
IN_POSITION = 0.005
#: mill_contour (SPEC 5).
DEFAULT_PATH = ((0.0, 0.0), (60.0, 0.0), (60.0, 40.0), (20.0, 40.0), (0.0, 20.0), (0.0, 0.0))


class GeometryError(ConfigError):
    """The corrected path cannot be built (reversing segments, a segment that vanishes or reverses)."""


def offset_path(points: Sequence[tuple[float, float]], r: float, closed: bool) -> list[tuple[float, float]]:
    """Corrected terminal points of a path offset by ``r`` to the left of travel (negative: right).

    Raises
    ------
    GeometryError
        naming the point or segment where no offset corner exists.
    """
    pts = [tuple(map(float, p)) for p in points]
    if closed and len(pts) > 2 and pts[0] == pts[-1]:
        pts = pts[:-1]
    n = len(pts)
    segs = list(range(n if closed else n - 1))
    units = []
    for k in segs:
        (x0, y0), (x1, y1) = pts[k], pts[(k + 1) % n]
        length = math.hypot(x1 - x0, y1 - y0)
        units.append(((x1 - x0) / length, (y1 - y0) / length))
    normals = [(-uy, ux) for ux, uy in units]
    corrected = []
    for i in range(n):
        incoming = (i - 1) % n if closed or i > 0 else None
        outgoing = i if closed or i < n - 1 else None
        px, py = pts[i]
        if incoming is None or outgoing is None:
            nx, ny = normals[outgoing if incoming is None else incoming]
            corrected.append((px + r * nx, py + r * ny))
            continue
        u1, u2 = units[incoming], units[outgoing]
        n1, n2 = normals[incoming], normals[outgoing]
        denominator = 1.0 + u1[0] * u2[0] + u1[1] * u2[1]
        if denominator < 1e-6:
            raise GeometryError(f"point[{i + 1}]", pts[i], "the path reverses here (segments at 180 degrees): "
                                                           "no offset corner exists")
        corrected.append((px + r * (n1[0] + n2[0]) / denominator, py + r * (n1[1] + n2[1]) / denominator))
    # A corrected segment must keep its direction and a length: else the offset has folded the path.
    for k in segs:
        (a, b) = corrected[k], corrected[(k + 1) % n]
        dx, dy = b[0] - a[0], b[1] - a[1]
        along = dx * units[k][0] + dy * units[k][1]
        if along <= 1e-9:
            raise GeometryError(f"point[{k + 1}]", pts[k], f"the correction {r:g} mm makes segment {k + 1} "
                                f"({'vanish' if abs(along) <= 1e-9 else 'run backwards'}): the offset path would "
                                "loop; use a smaller correction or a longer segment")
    return corrected


def _point_ports():
    ports = []
    for i in range(1, MAX_POINTS + 1):
        x, y = DEFAULT_PATH[i - 1] if i <= len(DEFAULT_PATH) else (0.0, 0.0)
        ports += [real(f"point[{i}].x", "parameter", x, "mm", f"terminal point {i}: X"),
                  real(f"point[{i}].y", "parameter", y, "mm", f"terminal point {i}: Y")]
    return tuple(ports)


class ContourInterpolator(Controller):
    MODEL_NAME = "ContourInterpolator"
    DESCRIPTION = ("Contour interpolator with cutter compensation: offset-segment intersection, DDA interpolation, "
                   "constant vector feed, override (GB 1,175,423)")
    SEED = "cutter-compensation-GB1175423.txt"
    STOP_TIME = 40.0

    PORTS = (
        integer("n_points", "parameter", len(DEFAULT_PATH), "number of terminal points", min=2, max=MAX_POINTS),
        *_point_ports(),
        boolean("closed", "parameter", True, "the path closes from the last point back to the first"),
        real("diameter_delta", "parameter", 0.4, "mm", "actual minus nominal cutter diameter"),
        integer("side", "parameter", -1, "side of the correction: +1 left of travel, -1 right", min=-1, max=1),
        real("feed", "parameter", 5.0, "mm/s", "vector feed rate", min=0.0),
        real("approach_feed", "parameter", 5.0, "mm/s", "vector feed of the approach (segment 0)", min=0.0),
        real("accel", "parameter", 500.0, "mm/s2", "path acceleration for start, stop, override and hold", min=0.0),
        real("inpos_timeout", "parameter", 2.0, "s", "in-position check: alarm when the axes have not reached the "
             "end point this long after the command stopped", min=0.0),
        real("dda_unit", "parameter", 0.001, "mm", "DDA output increment (one pulse)", min=0.0),
        real("x_start", "parameter", 0.0, "mm", "X command before the cycle (the axis's start position)"),
        real("y_start", "parameter", -10.0, "mm", "Y command before the cycle (the axis's start position)"),
        boolean("start", "input", False, "cycle start (rising edge)"),
        boolean("feed_hold", "input", False, "feed hold: decelerate and stop on the path while true"),
        real("feed_override", "input", 1.0, "1", "feed override", min=0.0, max=1.5),
        *servo_ports(("x", 0.0), ("y", 0.0)),
        integer("segment", "output", None, "segment being interpolated (0: approach)"),
        boolean("busy", "output", None, "a contour is running"),
        boolean("done", "output", None, "the contour is finished (until the next start)"),
        boolean("alarm", "output", None, "geometry cannot be corrected, or a bad input"),
    )

    def configure(self, values: Mapping[str, object]) -> None:
        n = int_param(values, "n_points", 2, MAX_POINTS)
        pts = [(real_param(values, f"point[{i}].x"), real_param(values, f"point[{i}].y")) for i in range(1, n + 1)]
        for i in range(1, n):
            require(pts[i] != pts[i - 1], f"point[{i + 1}]", pts[i], f"repeats point[{i}]: consecutive points "
                                                                     "must differ")
        self.closed = bool(values["closed"])
        if self.closed and pts[0] == pts[-1]:
            require(n >= 4, "n_points", n, "a closed path needs at least 3 distinct points")
        self.points = pts
        self.diameter_delta = real_param(values, "diameter_delta")
        side = int_param(values, "side")
        require(side in (1, -1), "side", side, "must be +1 (left of travel) or -1 (right)")
        self.side = side
        self.feed = real_param(values, "feed", positive=True)
        self.approach_feed = real_param(values, "approach_feed", positive=True)
        self.accel = real_param(values, "accel", positive=True)
        self.inpos_timeout = real_param(values, "inpos_timeout", positive=True)
        self.dda_unit = real_param(values, "dda_unit", positive=True)
        self.x_start = real_param(values, "x_start")
        self.y_start = real_param(values, "y_start")
        self.correction = self.side * self.diameter_delta / 2.0
        try:
            corrected = offset_path(pts, self.correction, self.closed)
            self.geometry_error = None
        except GeometryError as err:
            corrected, self.geometry_error = [], str(err)
        self.corrected = corrected
        # Tool path: the corrected points, back to the first one for a closed path.
        self.path = corrected + ([corrected[0]] if self.closed and corrected else [])

    def reset(self) -> None:
        self.cmd = [self.x_start, self.y_start]
        self.vff = [0.0, 0.0]
        self.segment = 0
        self.busy = False
        self.done = False
        self.alarm = self.geometry_error is not None
        if self.alarm:
            self.say("error", f"cutter compensation impossible: {self.geometry_error}")
        self.v = 0.0                      # path speed, mm/s
        self._seg = None                  # (start counts, span counts, N, length mm)
        self._k = 0.0                     # DDA iterations done in the present segment (fractional carry)
        self._start_was = False
        self._steps_since_end = 0
        self._halting = False             # controlled stop after an alarm
        self._positions = PositionGuard(("x_pos", "y_pos"))
        self._override = OverrideDial()
        self._outputs: dict[str, object] = {}
        self._publish()

    # -- the DDA ----------------------------------------------------------------------------------
    def _counts(self, value: float) -> int:
        return round(value / self.dda_unit)

    def _begin_segment(self, index: int) -> None:
        """Load the DDA with the span to the corrected point ``path[index]`` (index 0: approach to path[0])."""
        self.segment = index
        target = self.path[index]
        start = (self._counts(self.cmd[0]), self._counts(self.cmd[1]))
        span = (self._counts(target[0]) - start[0], self._counts(target[1]) - start[1])
        n_iter = 1 << max(1, max(abs(span[0]), abs(span[1]))).bit_length()    # normalised: MSB set
        length = math.hypot(span[0], span[1]) * self.dda_unit
        self._seg = (start, span, n_iter, length)

    def _dda_position(self, k: int) -> tuple[float, float]:
        (sx, sy), (dx, dy), n, _ = self._seg
        half = n >> 1                                      # accumulators preset to N/2: rounds the carries
        px = sx + (1 if dx >= 0 else -1) * ((half + k * abs(dx)) // n)
        py = sy + (1 if dy >= 0 else -1) * ((half + k * abs(dy)) // n)
        return px * self.dda_unit, py * self.dda_unit

    # -- stepping ---------------------------------------------------------------------------------
    def step(self, t: float, dt: float, inputs: Mapping[str, object]) -> dict[str, object]:
        bad = self._positions.check(inputs, dt) or finite_inputs(inputs, ("feed_override",))
        if bad or self._halting:
            if bad and not self.alarm:
                self.say("error", f"t = {t:.4f} s: {bad}; decelerating to rest on the path, cycle stopped")
            if bad:
                self.alarm, self.busy = True, False
                self._halting = self._seg is not None and self.v > 0.0
            if self._halting:
                self._advance(dt, 0.0, inputs, finishing=False)
                self._halting = self.v > 0.0
                if not self._halting:
                    self.vff = [0.0, 0.0]
            else:
                self.vff = [0.0, 0.0]
            self._start_was = bool(inputs["start"])
            return self._publish()
        start = bool(inputs["start"])
        if start and not self._start_was and not self.busy:
            if self.geometry_error:
                self.say("error", f"t = {t:.4f} s: start refused: {self.geometry_error}")
            else:
                self.alarm, self.done, self.busy = False, False, True
                self._k, self.v = 0.0, 0.0
                self._begin_segment(0)
        self._start_was = start
        if self.busy:
            override = self._override.read(self, t, float(inputs["feed_override"]))  # type: ignore[arg-type]
            rate = self.approach_feed if self.segment == 0 else self.feed
            self._advance(dt, 0.0 if inputs["feed_hold"] else rate * override, inputs)
        return self._publish()

    def _advance(self, dt: float, target: float, inputs: Mapping[str, object], finishing: bool = True) -> None:
        # distance left to the end of the whole contour, for the final deceleration
        remaining = self._remaining()
        a_dt = self.accel * dt
        v_old = self.v
        room = remaining - 0.5 * v_old * dt
        v_stop = -0.5 * a_dt + math.sqrt(0.25 * a_dt * a_dt + 2 * self.accel * room) if room > 0 else 0.0
        self.v = max(min(min(max(target, v_old - a_dt), v_old + a_dt), v_stop), 0.0)
        travel = 0.5 * (v_old + self.v) * dt
        x0, y0 = self.cmd
        while self._seg is not None:
            _, _, n, length = self._seg
            k_new = self._k + (travel * n / length if length > 0 else n)
            if k_new < n:
                self._k = k_new
                break
            # segment finished: carry the excess distance into the next one (the speed is continuous)
            travel = (k_new - n) * length / n if length > 0 else travel
            self._k = n
            self.cmd = list(self._dda_position(n))
            if self.segment + 1 < len(self.path):
                self._k = 0.0
                self._begin_segment(self.segment + 1)
            else:
                self._seg = None
        if self._seg is not None:
            self.cmd = list(self._dda_position(int(self._k)))
            direction = self._direction()
            self.vff = [self.v * direction[0], self.v * direction[1]]
        else:
            self.vff = [0.0, 0.0]
            self.v = 0.0
            if not finishing:
                return
            self._steps_since_end += 1
            # the actual axes must stand at this controller's own end point, not only be in position
            arrived = all(abs(float(inputs[f"{a}_pos"]) - c) <= IN_POSITION  # type: ignore[arg-type]
                          for a, c in zip("xy", self.cmd))
            if self._steps_since_end >= 2 and inputs["x_in_position"] and inputs["y_in_position"] and arrived:
                self.busy, self.done, self._steps_since_end = False, True, 0
            elif self._steps_since_end * dt > self.inpos_timeout:
                self._steps_since_end = 0
                self.alarm, self.busy = True, False
                self.say("error", f"in-position check: the axes stand at ({float(inputs['x_pos']):.4f}, "  # type: ignore[arg-type]
                                  f"{float(inputs['y_pos']):.4f}), not at the end point ({self.cmd[0]:.4f}, "  # type: ignore[arg-type]
                                  f"{self.cmd[1]:.4f}), {self.inpos_timeout:g} s after the command stopped")

    def _direction(self) -> tuple[float, float]:
        _, (dx, dy), _, _ = self._seg
        length = math.hypot(dx, dy)
        return (dx / length, dy / length) if length else (0.0, 0.0)

    def _remaining(self) -> float:
        if self._seg is None:
            return 0.0
        _, _, n, length = self._seg
        left = length * (1.0 - self._k / n)
        for i in range(self.segment + 1, len(self.path)):
            (ax, ay), (bx, by) = self.path[i - 1], self.path[i]
            left += math.hypot(bx - ax, by - ay)
        return left

    def _publish(self) -> dict[str, object]:
        out = self._outputs
        out["x_cmd"], out["y_cmd"] = self.cmd
        out["x_vff"], out["y_vff"] = self.vff
        out["segment"] = self.segment
        out["busy"], out["done"], out["alarm"] = self.busy, self.done, self.alarm
        return out
