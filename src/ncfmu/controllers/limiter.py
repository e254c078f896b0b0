"""Operating-area limiter (seed: JP S61-33202, NC operating-area limiter).

A limit table splits a reference axis into regions by ordered upper boundaries
(``region[i].ref_max``); region i is ``ref_max[i-1] < ref <= ref_max[i]`` (region 1 is open
below). Each region allows its own range ``[lim_min, lim_max]`` on the limited axis, so the envelope
is stepped, not rectangular. A reference position above the last boundary is outside the table.

Every monitor period (5 ms in the seed) the limiter finds the region (binary search, O(log n);
the seed scans linearly) and compares the limited axis with that region's range. On a violation it
blocks the direction that was being commanded -- on whichever axis moved into the violation, as the
seed resets that bit of its movement-axis register -- by holding that axis's last allowed command
with zero velocity feed-forward. Motion in the opposite direction passes at once, so the axis can be
backed out without re-homing. A blocked direction is released, and ``alarm`` cleared, once the
position is inside and a step in that direction would stay inside -- after backing out, or after the
other axis has moved clear (the wheel retracted, the table may travel again). An input that ran ahead
while held is then followed accelerating at ``decel``, never with a jump.

It sits between a controller and the servos and judges the position it commands (its gated output,
like the seed's current-position counter); with ``use_actual`` also the servo feedback (the
stricter of both). With ``predictive`` it judges where the axis can get: the command plus one
monitor period of travel, the stopping distance at ``decel`` and the servo's following error, so the
boundary is not crossed at all.
"""

from __future__ import annotations

import bisect
from collections.abc import Mapping, Sequence

import math

from ..errors import require
from ..ports import boolean, integer, real
from .base import Controller, finite_inputs, int_param, real_param

MAX_REGIONS = 32
REF_PLUS, REF_MINUS, LIM_PLUS, LIM_MINUS = 1, 2, 4, 8
BIG = 1.0e6

#: The lathe_roughing table (SPEC 5): reference Z, limited X; X >= 40 for Z <= -45 (the chuck).
DEFAULT_TABLE = ((-45.0, 40.0, BIG), (BIG, -BIG, BIG))


def find_region(boundaries: Sequence[float], ref: float) -> int:
    """1-based region of ``ref`` (``ref <= boundaries[i-1]``, the first such); 0 above the table."""
    i = bisect.bisect_left(boundaries, ref)
    return i + 1 if i < len(boundaries) else 0


def _table_ports():
    ports = []
    for i in range(1, MAX_REGIONS + 1):
        ref_max, lo, hi = DEFAULT_TABLE[i - 1] if i <= len(DEFAULT_TABLE) else (BIG + i, -BIG, BIG)
        ports += [
            real(f"region[{i}].ref_max", "parameter", ref_max, "mm", f"region {i}: upper boundary on the reference axis"),
            real(f"region[{i}].lim_min", "parameter", lo, "mm", f"region {i}: lowest allowed limited-axis position"),
            real(f"region[{i}].lim_max", "parameter", hi, "mm", f"region {i}: highest allowed limited-axis position"),
        ]
    return tuple(ports)


class AreaLimiter(Controller):
    MODEL_NAME = "AreaLimiter"
    DESCRIPTION = ("Operating-area limiter: stepped, region-dependent limits; blocks only the offending direction "
                   "(JP S61-33202)")
    SEED = "area-limiter-JPS6133202.txt"
    STOP_TIME = 1.0

    PORTS = (
        integer("n_regions", "parameter", len(DEFAULT_TABLE), "number of regions in the limit table", min=1, max=MAX_REGIONS),
        *_table_ports(),
        real("monitor_period", "parameter", 0.005, "s", "monitor period (the seed's 5 ms interrupt)", min=0.0),
        boolean("predictive", "parameter", False, "judge the position the axis can reach (command + travel "
                "in one period + stopping distance + following error)"),
        boolean("use_actual", "parameter", False, "also judge the servo feedback ref_pos/lim_pos (the stricter)"),
        real("ref_start", "parameter", 0.0, "mm", "reference-axis command before the first step (the axis's start position)"),
        real("lim_start", "parameter", 0.0, "mm", "limited-axis command before the first step (the axis's start position)"),
        real("decel", "parameter", 500.0, "mm/s2", "deceleration assumed for the stopping distance (predictive)", min=0.0),
        real("ref_cmd_in", "input", 0.0, "mm", "reference-axis position command from the controller"),
        real("lim_cmd_in", "input", 0.0, "mm", "limited-axis position command from the controller"),
        real("ref_vff_in", "input", 0.0, "mm/s", "reference-axis velocity feed-forward from the controller"),
        real("lim_vff_in", "input", 0.0, "mm/s", "limited-axis velocity feed-forward from the controller"),
        real("ref_pos", "input", 0.0, "mm", "actual reference-axis position (servo feedback)"),
        real("lim_pos", "input", 0.0, "mm", "actual limited-axis position (servo feedback)"),
        real("ref_cmd", "output", None, "mm", "gated reference-axis position command"),
        real("lim_cmd", "output", None, "mm", "gated limited-axis position command"),
        real("ref_vff", "output", None, "mm/s", "gated reference-axis velocity feed-forward"),
        real("lim_vff", "output", None, "mm/s", "gated limited-axis velocity feed-forward"),
        boolean("alarm", "output", None, "envelope violated (until back inside)"),
        integer("region", "output", None, "region of the reference axis (0: above the table)"),
        integer("blocked", "output", None, "blocked directions: 1 ref+, 2 ref-, 4 lim+, 8 lim-"),
    )

    def configure(self, values: Mapping[str, object]) -> None:
        n = int_param(values, "n_regions", 1, MAX_REGIONS)
        bounds, lows, highs = [], [], []
        for i in range(1, n + 1):
            b = real_param(values, f"region[{i}].ref_max")
            lo = real_param(values, f"region[{i}].lim_min")
            hi = real_param(values, f"region[{i}].lim_max")
            if bounds:
                require(b > bounds[-1], f"region[{i}].ref_max", b,
                        f"boundaries must increase strictly (region[{i - 1}].ref_max = {bounds[-1]:g})")
            require(lo <= hi, f"region[{i}].lim_min", lo, f"must be <= region[{i}].lim_max = {hi:g}")
            bounds.append(b), lows.append(lo), highs.append(hi)
        self.n_regions = n
        self.ref_max, self.lim_min, self.lim_max = bounds, lows, highs
        self.monitor_period = real_param(values, "monitor_period", positive=True)
        self.decel = real_param(values, "decel", positive=True)
        self.predictive = bool(values["predictive"])
        self.use_actual = bool(values["use_actual"])
        self.ref_start = real_param(values, "ref_start")
        self.lim_start = real_param(values, "lim_start")

    @classmethod
    def with_table(cls, table: Sequence[tuple[float, float, float]], **parameters: object) -> "AreaLimiter":
        """Build from ``(ref_max, lim_min, lim_max)`` rows."""
        flat: dict[str, object] = {"n_regions": len(table)}
        for i, (b, lo, hi) in enumerate(table, start=1):
            flat[f"region[{i}].ref_max"], flat[f"region[{i}].lim_min"], flat[f"region[{i}].lim_max"] = b, lo, hi
        flat.update(parameters)
        return cls(**flat)

    def reset(self) -> None:
        self.ref_out, self.lim_out = self.ref_start, self.lim_start
        self.ref_vff = self.lim_vff = 0.0
        self.blocked = 0
        self._catch_up = [0.0, 0.0]                # extra speed while following an input that ran ahead
        self._block_speed = {REF_PLUS: 0.0, REF_MINUS: 0.0, LIM_PLUS: 0.0, LIM_MINUS: 0.0}
        self.alarm = False
        self.region = 0
        self.clock = self.monitor_period        # monitor at the first step
        self._tick_ref, self._tick_lim = self.ref_out, self.lim_out   # gated positions at the last tick
        self.fault = None
        self._outputs: dict[str, object] = {}
        self._publish()

    # -- the envelope -----------------------------------------------------------------------------
    def inside(self, ref: float, lim: float) -> bool:
        r = find_region(self.ref_max, ref)
        return r > 0 and self.lim_min[r - 1] <= lim <= self.lim_max[r - 1]

    def _violations(self, ref: float, lim: float, ref_from: float, dir_ref: int, dir_lim: int) -> int:
        """Directions to block for the judged point (ref, lim); ``ref_from`` is where the reference came from."""
        r = find_region(self.ref_max, ref)
        if r > 0 and self.lim_min[r - 1] <= lim <= self.lim_max[r - 1]:
            return 0
        mask = 0
        if r > 0:
            if lim > self.lim_max[r - 1] and dir_lim > 0:
                mask |= LIM_PLUS
            if lim < self.lim_min[r - 1] and dir_lim < 0:
                mask |= LIM_MINUS
        # The reference axis is the offender when it carried the tool into this region (or off the table).
        if dir_ref != 0 and (r == 0 or find_region(self.ref_max, ref_from) != r):
            mask |= REF_PLUS if dir_ref > 0 else REF_MINUS
        if mask == 0:
            # Outside with nothing moving that way yet: block whatever motion would deepen it.
            if r == 0:
                mask |= REF_PLUS
            elif lim > self.lim_max[r - 1]:
                mask |= LIM_PLUS
            else:
                mask |= LIM_MINUS
        return mask

    def _lookahead(self, v: float, fe: float) -> float:
        """How far beyond its command an axis moving at ``v`` can get (predictive mode)."""
        return abs(v) * self.monitor_period + v * v / (2.0 * self.decel) + abs(fe)

    # -- stepping ---------------------------------------------------------------------------------
    def step(self, t: float, dt: float, inputs: Mapping[str, object]) -> dict[str, object]:
        bad = finite_inputs(inputs, ("ref_cmd_in", "lim_cmd_in", "ref_vff_in", "lim_vff_in", "ref_pos", "lim_pos"))
        if bad:
            # Hold both axes where they are: a NaN never reaches a servo.
            if self.fault != bad:
                self.say("error", f"t = {t:.4f} s: {bad}; holding the last commands")
            self.fault = bad
            self.alarm = True
            self.ref_vff = self.lim_vff = 0.0
            return self._publish()
        self.fault = None
        ref_in, lim_in = float(inputs["ref_cmd_in"]), float(inputs["lim_cmd_in"])

        if self.blocked:
            self._release(t, ref_in, lim_in, float(inputs["ref_vff_in"]), float(inputs["lim_vff_in"]))
        # Gate: a blocked direction holds; anything else passes at once (catching up without a jump).
        self.ref_out, self.ref_vff = self._gate(0, ref_in, float(inputs["ref_vff_in"]), self.ref_out, dt,
                                                REF_PLUS, REF_MINUS)
        self.lim_out, self.lim_vff = self._gate(1, lim_in, float(inputs["lim_vff_in"]), self.lim_out, dt,
                                                LIM_PLUS, LIM_MINUS)

        self.clock += dt
        if self.clock >= self.monitor_period - 1e-12:
            self.clock = 0.0
            self._monitor(t, ref_in, lim_in, float(inputs["ref_pos"]), float(inputs["lim_pos"]))
        return self._publish()

    def _gate(self, axis: int, cmd: float, vff: float, held: float, dt: float, plus: int, minus: int):
        if (cmd > held and self.blocked & plus) or (cmd < held and self.blocked & minus):
            self._catch_up[axis] = 0.0
            return held, 0.0
        gap = cmd - held
        # An interpolator's step may exceed vff*dt by half an acceleration step: that is motion, pass it.
        if abs(gap) <= (abs(vff) + self.decel * dt) * dt + 1e-9:
            self._catch_up[axis] = 0.0
            return cmd, vff
        # The input ran ahead while this direction was held: follow it accelerating at ``decel``.
        self._catch_up[axis] += self.decel * dt
        step = math.copysign(min(abs(gap), (abs(vff) + self._catch_up[axis]) * dt), gap)
        return held + step, step / dt

    def _release(self, t: float, ref_in: float, lim_in: float, ref_vff_in: float, lim_vff_in: float) -> None:
        """Free a blocked direction once a step that way from the present position stays inside.

        It is freed either by backing out (a move against it, as in the seed) or because the other axis
        moved so that this direction is allowed again (the wheel retracted, the table may travel).
        """
        freed = 0
        for bit, axis_ref, sign, vff in ((REF_PLUS, True, 1, ref_vff_in), (REF_MINUS, True, -1, ref_vff_in),
                                         (LIM_PLUS, False, 1, lim_vff_in), (LIM_MINUS, False, -1, lim_vff_in)):
            if not self.blocked & bit:
                continue
            # probe as far as the axis could go at the speed it was blocked at (or is now asked for)
            speed = max(abs(vff), self._block_speed[bit])
            probe = sign * max(self._lookahead(speed, 0.0) if self.predictive else speed * self.monitor_period, 1e-6)
            ref, lim = (self.ref_out + probe, self.lim_out) if axis_ref else (self.ref_out, self.lim_out + probe)
            if self.inside(self.ref_out, self.lim_out) and self.inside(ref, lim):
                freed |= bit
        if freed:
            self.blocked &= ~freed
            self.say("info", f"t = {t:.4f} s: inside the envelope again; releasing {_mask_text(freed)}")
            self.alarm = bool(self.blocked)

    def _monitor(self, t: float, ref_in: float, lim_in: float, ref_pos: float, lim_pos: float) -> None:
        dir_ref = _sign(self.ref_out - self._tick_ref) or _sign(ref_in - self.ref_out)
        dir_lim = _sign(self.lim_out - self._tick_lim) or _sign(lim_in - self.lim_out)
        points = [(self.ref_out, self.lim_out, self._tick_ref)]
        if self.use_actual:
            points.append((ref_pos, lim_pos, self._tick_ref))
        if self.predictive:
            fe_ref, fe_lim = self.ref_out - ref_pos, self.lim_out - lim_pos
            reach_ref = dir_ref * self._lookahead(self.ref_vff, fe_ref)
            reach_lim = dir_lim * self._lookahead(self.lim_vff, fe_lim)
            points = [(r + reach_ref, l + reach_lim, r) for r, l, _ in points]
        new = 0
        for ref, lim, ref_from in points:
            new |= self._violations(ref, lim, ref_from, dir_ref, dir_lim)
        self.region = find_region(self.ref_max, self.ref_out)
        if new & ~self.blocked:
            for bit, v in ((REF_PLUS, self.ref_vff), (REF_MINUS, self.ref_vff), (LIM_PLUS, self.lim_vff),
                           (LIM_MINUS, self.lim_vff)):
                if new & bit & ~self.blocked:
                    self._block_speed[bit] = abs(v)
            self.say("warning", f"t = {t:.4f} s: envelope violated in region {self.region} "
                                f"(ref {self.ref_out:.4f}, lim {self.lim_out:.4f}); blocking {_mask_text(new)}")
            if new & (REF_PLUS | REF_MINUS):
                self.ref_vff = 0.0
            if new & (LIM_PLUS | LIM_MINUS):
                self.lim_vff = 0.0
        self.blocked |= new
        self.alarm = bool(self.blocked) or bool(new)
        self._tick_ref, self._tick_lim = self.ref_out, self.lim_out

    def _publish(self) -> dict[str, object]:
        out = self._outputs
        out["ref_cmd"], out["lim_cmd"] = self.ref_out, self.lim_out
        out["ref_vff"], out["lim_vff"] = self.ref_vff, self.lim_vff
        out["alarm"], out["region"], out["blocked"] = self.alarm, self.region, self.blocked
        return out


def _sign(x: float) -> int:
    return (x > 1e-12) - (x < -1e-12)


def _mask_text(mask: int) -> str:
    names = [(REF_PLUS, "ref+"), (REF_MINUS, "ref-"), (LIM_PLUS, "lim+"), (LIM_MINUS, "lim-")]
    return ", ".join(n for bit, n in names if mask & bit) or "nothing"
