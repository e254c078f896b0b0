"""Operating-area limiter (seed: JP S61-33202, NC operating-area limiter).

A limit table splits a reference axis into regions by ordered upper boundaries
(``region[i].ref_max``); region i is ``ref_max[i-1] < ref <= ref_max[i]`` (region 1 is open
below). Each region allows its own range ``[lim_min, lim_max]`` on the limited axis, so the envelope
is stepped, not rectangular. A reference position above the last boundary is outside the table.

Every monitor period (5 ms in the seed) the limiter finds the region (the cached one while the position stays
in it, else a binary search, O(log n);
the seed scans linearly) and compares the limited axis with that region's range. On a violation it
blocks the direction that was being commanded -- on whichever axis moved into the violation, as the
seed resets that bit of its movement-axis register. Motion in the opposite direction passes at once,
so the axis can be backed out without re-homing.

Stops are controlled, as in every ncfmu controller: a blocked direction is not a frozen command. The gated
output of that axis decelerates at ``decel`` to rest and holds there (velocity feed-forward 0 at rest); the
command never steps its velocity. Without ``predictive`` the violation is seen after the fact, so the
gated command may pass the boundary by at most ``v * (monitor_period + dt) + v**2 / (2 * decel)``
(``v``: its speed, never more than the fastest the input asked for -- a rejoin does not outrun the input;
:meth:`AreaLimiter.overshoot_bound`). With ``predictive`` the limiter governs
the speed every step: each axis may move toward a boundary only as fast as it can still stop
``margin`` before it at ``decel`` (the boundary being the nearest region edge that the other axis,
within its own stopping reach, makes forbidden), so the command stops at the boundary and the actual
axis never crosses. Then ``alarm``/``blocked`` say that the *input* asks to go outside.

No deadlock: a command that stays inside is always followed -- passed at once when it is consistent
with its feed-forward and steps its velocity by at most ``decel * dt``, otherwise (after a hold, a braking, a
start away from the input, or the input's own velocity step) rejoined without a jump, closing the gap at
``decel`` and never faster than the input has asked for since the axis stopped passing (behind a moving input
it trails it until the input slows; an input that has not moved is rejoined at up to ``max_speed``). A
blocked direction is released once the position is inside and a step in that direction stays inside.

Absurd inputs -- NaN or infinite values, a position beyond any machine, a feed-forward beyond
``max_speed``, a command jump beyond what the axis can do in one step -- bring both axes to a
controlled stop with ``alarm`` and one log line. A jump latches until the input comes back to within
one step of the gated output (the controller has re-based on the axis); the start is exempt: the first
input is rejoined.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping, Sequence
from typing import ClassVar

from ..errors import require
from ..ports import boolean, integer, real
from .base import POSITION_LIMIT, Controller, PositionGuard, as_float, int_param, real_param
from .motion import stop_speed
from .mypyc_compat import mypyc_attr

MAX_REGIONS = 32
REF_PLUS, REF_MINUS, LIM_PLUS, LIM_MINUS = 1, 2, 4, 8
BIG = 1.0e6

def find_region(boundaries: Sequence[float], ref: float) -> int:
    """1-based region of ``ref`` (``ref <= boundaries[i-1]``, the first such); 0 above the table."""
    i = bisect.bisect_left(boundaries, ref)
    return i + 1 if i < len(boundaries) else 0


def _table_ports():
    ports = []
    for i in range(1, MAX_REGIONS + 1):
        # unset regions lie beyond each other and limit nothing
        ref_max, lo, hi = BIG + i - 1, -BIG, BIG
        ports += [
            real(f"region[{i}].ref_max", "parameter", ref_max, "mm",
                 f"region {i}: upper boundary on the reference axis"),
            real(f"region[{i}].lim_min", "parameter", lo, "mm", f"region {i}: lowest allowed limited-axis position"),
            real(f"region[{i}].lim_max", "parameter", hi, "mm", f"region {i}: highest allowed limited-axis position"),
        ]
    return tuple(ports)




@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)
class AreaLimiter(Controller):
    MODEL_NAME = "AreaLimiter"
    DESCRIPTION = ("Operating-area limiter: stepped, region-dependent limits; blocks only the offending direction "
                   "(JP S61-33202)")
    SEED = "area-limiter-JPS6133202.txt"
    STOP_TIME = 1.0
    # The region the reference axis is in, cached with its bounds and range (_enter): derived from the table alone,
    # whichever region it holds, so not saved in a state -- a restored limiter keeps its fresh cache, a valid one.
    # The status last written into ``out`` and that dict (_publish): a cache of what ``out`` holds.
    DERIVED: ClassVar[tuple[str, ...]] = ("_reg", "_reg_lo", "_reg_hi", "_reg_min", "_reg_max", "_status", "_status_of")

    PORTS = (
        integer("n_regions", "parameter", 1, "number of regions in the limit table",
                min=1, max=MAX_REGIONS),
        *_table_ports(),
        real("monitor_period", "parameter", 0.005, "s", "monitor period (the seed's 5 ms interrupt)", min=0.0,
             min_exclusive=True),
        boolean("predictive", "parameter", False, "govern the speed so that each axis can still stop 'margin' before "
                "the boundary at 'decel': the command stops at the boundary, the actual axis never crosses"),
        boolean("use_actual", "parameter", False, "also judge the servo feedback ref_pos/lim_pos (the stricter)"),
        real("ref_start", "parameter", 0.0, "mm",
             "reference-axis command before the first step (the axis's start position)", min=-POSITION_LIMIT,
             max=POSITION_LIMIT),
        real("lim_start", "parameter", 0.0, "mm",
             "limited-axis command before the first step (the axis's start position)", min=-POSITION_LIMIT,
             max=POSITION_LIMIT),
        real("decel", "parameter", 500.0, "mm/s2", "deceleration of every controlled stop and rejoin, and the one "
             "assumed for the stopping distance (predictive)", min=0.0, min_exclusive=True),
        real("max_speed", "parameter", 500.0, "mm/s", "fastest the axes can move: a larger feed-forward, or a command "
             "jump beyond max_speed * dt, is absurd (hold, alarm); rejoins never go faster", min=0.0,
             min_exclusive=True),
        real("margin", "parameter", 0.05, "mm", "predictive: the command stops this far before the boundary", min=0.0),
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
        boolean("alarm", "output", None, "envelope violated or asked for, or an absurd input (until resolved)"),
        integer("region", "output", None, "region of the reference axis (0: above the table)"),
        integer("blocked", "output", None, "blocked directions: 1 ref+, 2 ref-, 4 lim+, 8 lim-"),
    )

    def configure(self, values: Mapping[str, object]) -> None:
        n = int_param(values, "n_regions")
        bounds: list[float] = []
        lows: list[float] = []
        highs: list[float] = []
        for i in range(1, n + 1):
            b = real_param(values, f"region[{i}].ref_max")
            lo = real_param(values, f"region[{i}].lim_min")
            hi = real_param(values, f"region[{i}].lim_max")
            if bounds:
                require(b > bounds[-1], f"region[{i}].ref_max", b,
                        f"boundaries must increase strictly (region[{i - 1}].ref_max = {bounds[-1]:g})")
            require(lo <= hi, f"region[{i}].lim_min", lo, f"must be <= region[{i}].lim_max = {hi:g}")
            bounds.append(b)
            lows.append(lo)
            highs.append(hi)
        self.n_regions = n
        self.ref_max, self.lim_min, self.lim_max = bounds, lows, highs
        self.monitor_period = real_param(values, "monitor_period")
        self.decel = real_param(values, "decel")
        self.max_speed = real_param(values, "max_speed")
        self.margin = real_param(values, "margin")
        self.predictive = bool(values["predictive"])
        require(self.margin >= 1e-3 or not self.predictive, "margin", self.margin,
                "must be >= 0.001 mm with predictive (a stop computed to end exactly on the boundary can end a "
                "rounding past it)")
        self.use_actual = bool(values["use_actual"])
        self.ref_start = real_param(values, "ref_start")
        self.lim_start = real_param(values, "lim_start")

    @classmethod
    def with_table(cls, table: Sequence[tuple[float, float, float]], **parameters: object) -> AreaLimiter:
        """Build from ``(ref_max, lim_min, lim_max)`` rows."""
        flat: dict[str, object] = {"n_regions": len(table)}
        for i, (b, lo, hi) in enumerate(table, start=1):
            flat[f"region[{i}].ref_max"], flat[f"region[{i}].lim_min"], flat[f"region[{i}].lim_max"] = b, lo, hi
        flat.update(parameters)
        return cls(**flat)

    def overshoot_bound(self, speed: float, dt: float) -> float:
        """Without ``predictive``: how far past a boundary the gated command of an axis moving at ``speed``
        can get -- one monitor period and one step before the violation is seen, then the stop at ``decel``.
        ``speed`` may be the fastest the input has asked for: the gated command is never faster (a rejoin
        trails its input rather than outrun it)."""
        return speed * (self.monitor_period + dt) + speed * speed / (2.0 * self.decel) + 1e-9

    def reset(self) -> None:
        self.pos = [self.ref_start, self.lim_start]   # gated commands (ref, lim)
        self.vel = [0.0, 0.0]                          # gated velocity feed-forwards
        self.passing = [True, True]                    # the output is the input (else: governed/rejoining)
        self._rejoin_speed = [0.0, 0.0]   # fastest speed asked for since the axis stopped passing: caps the rejoin
        self.hard = 0          # blocks from a violation of the gated (or actual) position: the axis stops
        self.soft = 0          # predictive: the input asks to leave the envelope (the governor holds it)
        self.blocked = 0
        self._block_speed = {REF_PLUS: 0.0, REF_MINUS: 0.0, LIM_PLUS: 0.0, LIM_MINUS: 0.0}
        self._prev_in: tuple[float, float] | None = None
        self._jump = [False, False]
        self._jump_text = ["", ""]
        self._feedback = PositionGuard(("ref_pos", "lim_pos"))
        self.alarm = False
        self._enter(find_region(self.ref_max, self.ref_start))
        self.region = self._region(self.ref_start)
        self.clock = self.monitor_period        # monitor at the first step
        self._tick = list(self.pos)             # gated positions at the last tick
        self.fault: str | None = None
        self._outputs: dict[str, object] = {}
        self._status: tuple[bool, int, int] = (False, 0, 0)
        self._status_of: dict[str, object] | None = None
        self._publish()

    # -- the envelope -----------------------------------------------------------------------------
    def _enter(self, r: int) -> None:
        """Cache region ``r`` (1..n; 0 above the table): the reference positions it spans, ``_reg_lo < ref <=
        _reg_hi`` (find_region's rule), and its range on the limited axis. A step that stays in it (nearly
        every step) then finds its region in two comparisons instead of a binary search."""
        n = self.n_regions
        self._reg = r
        if r == 0:                       # above the last boundary: no range (the callers test r > 0 first)
            self._reg_lo, self._reg_hi = self.ref_max[n - 1], math.inf
            self._reg_min, self._reg_max = math.inf, -math.inf
            return
        self._reg_lo = self.ref_max[r - 2] if r > 1 else -math.inf
        self._reg_hi = self.ref_max[r - 1]
        self._reg_min, self._reg_max = self.lim_min[r - 1], self.lim_max[r - 1]

    def _region(self, ref: float) -> int:
        """:func:`find_region` of ``ref``, the cached region when ``ref`` is in it (NaN never is)."""
        if self._reg_lo < ref <= self._reg_hi:
            return self._reg
        r = find_region(self.ref_max, ref)
        self._enter(r)
        return r

    def inside(self, ref: float, lim: float) -> bool:
        r = self._region(ref)
        return r > 0 and self.lim_min[r - 1] <= lim <= self.lim_max[r - 1]

    def _violations(self, ref: float, lim: float, ref_from: float, dir_ref: int, dir_lim: int) -> int:
        """Directions to block for the judged point (ref, lim); ``ref_from`` is where the reference came from."""
        r = self._region(ref)
        if r > 0 and self.lim_min[r - 1] <= lim <= self.lim_max[r - 1]:
            return 0
        mask = 0
        if r > 0:
            if lim > self.lim_max[r - 1] and dir_lim > 0:
                mask |= LIM_PLUS
            if lim < self.lim_min[r - 1] and dir_lim < 0:
                mask |= LIM_MINUS
        # The reference axis is the offender when it carried the tool into this region. Off the table (above
        # its last boundary) only going further up is blocked: going down leads back onto it.
        if r == 0:
            mask |= REF_PLUS
        elif dir_ref != 0 and self._region(ref_from) != r:
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

    def _reach(self, axis: int, dt: float) -> tuple[float, float]:
        """Where an axis can get before it stops (one step, then braking at ``decel``)."""
        v = self.vel[axis]
        d = v * dt + v * abs(v) / (2.0 * self.decel)
        p = self.pos[axis]
        return p + min(0.0, d), p + max(0.0, d)

    def _rooms(self, dt: float) -> tuple[float, float, float, float]:
        """Predictive: distance each axis may still travel (ref+, ref-, lim+, lim-) to ``margin`` before the
        nearest boundary that the other axis, anywhere within its stopping reach, makes forbidden."""
        m, n = self.margin, self.n_regions
        ref, lim = self.pos
        bounds, lows, highs = self.ref_max, self.lim_min, self.lim_max
        # each axis's reach (_reach written out: min(0.0, d) and max(0.0, d) as the same choices)
        two_decel = 2.0 * self.decel
        v = self.vel[1]
        d = v * dt + v * abs(v) / two_decel
        lim_lo, lim_hi = lim + (d if d < 0.0 else 0.0), lim + (d if d > 0.0 else 0.0)
        v = self.vel[0]
        d = v * dt + v * abs(v) / two_decel
        ref_lo, ref_hi = ref + (d if d < 0.0 else 0.0), ref + (d if d > 0.0 else 0.0)
        inf = math.inf
        # limited axis: the tightest range over the regions the reference axis may be in (find_region written
        # out: bisect, 0 above the table)
        if self._reg_lo < ref_lo and ref_hi <= self._reg_hi and self._reg > 0:
            # the whole reach in the cached region (nearly every step): its range, and ref's region is it too
            r = self._reg
            lim_plus = self._reg_max - m - lim
            lim_minus = lim - (self._reg_min + m)
            return self._ref_rooms(r, ref, lim_lo, lim_hi, lim_plus, lim_minus)
        r1 = bisect.bisect_left(bounds, ref_lo) + 1
        if r1 > n:                       # off the table: the reference axis must back out; X is no worse
            lim_plus = lim_minus = inf
        else:
            last = bisect.bisect_left(bounds, ref_hi, r1 - 1) + 1
            if last > n:
                last = n
            if last == r1:               # one region (the common case): its range, no slice
                lim_plus = highs[r1 - 1] - m - lim
                lim_minus = lim - (lows[r1 - 1] + m)
            else:
                lim_plus = min(highs[r1 - 1:last]) - m - lim
                lim_minus = lim - (max(lows[r1 - 1:last]) + m)

        r = bisect.bisect_left(bounds, ref) + 1     # n + 1 above the table
        self._enter(r if r <= n else 0)             # crossed into another region: cache it
        return self._ref_rooms(r, ref, lim_lo, lim_hi, lim_plus, lim_minus)

    def _ref_rooms(self, r: int, ref: float, lim_lo: float, lim_hi: float, lim_plus: float,
                   lim_minus: float) -> tuple[float, float, float, float]:
        """_rooms of the reference axis in region ``r`` (n + 1 above the table), with the limited axis's."""
        m, n = self.margin, self.n_regions
        bounds, lows, highs = self.ref_max, self.lim_min, self.lim_max
        inf = math.inf
        # region j forbids the limited axis's reach: lim_lo < lim_min[j - 1] or lim_hi > lim_max[j - 1]
        # (written out in both loops: a closure made every step costs more than the test)
        ref_plus = bounds[n - 1] - m - ref          # the end of the table
        for j in range(r + 1, n + 1):
            if lim_lo < lows[j - 1] or lim_hi > highs[j - 1]:
                ref_plus = bounds[j - 2] - m - ref  # region j starts just above ref_max[j-2]
                break
        ref_minus = inf
        for j in range(r - 1, 0, -1):
            if lim_lo < lows[j - 1] or lim_hi > highs[j - 1]:
                ref_minus = ref - bounds[j - 1] - m  # region j ends at ref_max[j-1], inclusive
                break
        return ref_plus, ref_minus, lim_plus, lim_minus

    def _windows(self, dt: float) -> tuple[float, float, float, float]:
        """Velocity window of each axis for this step: (ref lo, ref hi, lim lo, lim hi)."""
        s = self.max_speed
        lo0, hi0, lo1, hi1 = -s, s, -s, s
        hard = self.hard
        if hard:
            if hard & REF_PLUS:
                hi0 = 0.0
            if hard & REF_MINUS:
                lo0 = 0.0
            if hard & LIM_PLUS:
                hi1 = 0.0
            if hard & LIM_MINUS:
                lo1 = 0.0
        if self.predictive:
            rp, rm, lp, lm = self._rooms(dt)
            a = self.decel
            v0, v1 = self.vel
            # stop_speed grows with its room: past ``far`` (the rest of room that the root's equation needs at
            # max_speed, with a relative margin of 1e-6 -- far beyond the root's rounding) the speed is above
            # max_speed and min/max below would keep the window as it is: the same window, without the root
            far = (s * s / (2.0 * a) + 0.5 * s * dt) * (1.0 + 1e-6) + 1e-9
            # (the test's own rounding is far inside that margin; a room of inf, off the table, gives a NaN
            # speed that min/max ignore -- skipped just as well)
            half_dt = 0.5 * dt
            if rp - half_dt * (v0 if v0 > 0.0 else 0.0) < far:
                hi0 = min(hi0, stop_speed(rp, v0, a, dt))
            if rm - half_dt * (-v0 if v0 < 0.0 else 0.0) < far:
                lo0 = max(lo0, -stop_speed(rm, -v0, a, dt))
            if lp - half_dt * (v1 if v1 > 0.0 else 0.0) < far:
                hi1 = min(hi1, stop_speed(lp, v1, a, dt))
            if lm - half_dt * (-v1 if v1 < 0.0 else 0.0) < far:
                lo1 = max(lo1, -stop_speed(lm, -v1, a, dt))
        return lo0, hi0, lo1, hi1

    # -- stepping ---------------------------------------------------------------------------------
    def step(self, t: float, dt: float, inputs: Mapping[str, object]) -> dict[str, object]:
        cmd = (inputs["ref_cmd_in"], inputs["lim_cmd_in"])
        vff = (inputs["ref_vff_in"], inputs["lim_vff_in"])
        bad = self._absurd(cmd, vff, inputs, dt)  # type: ignore[arg-type]
        if bad:
            # Both axes come to a controlled stop where they are: nothing absurd reaches a servo.
            if self.fault != bad:
                self.say("error", f"t = {t:.4f} s: {bad}; both axes stopped, holding")
            self.fault = bad
            for axis in (0, 1):
                self._brake(axis, dt)
            self.alarm = True
            return self._publish()
        if self.fault:
            self.say("info", f"t = {t:.4f} s: inputs sane again; following the commands")
            self.fault = None
        c = (as_float(cmd[0]), as_float(cmd[1]))
        v_in = (as_float(vff[0]), as_float(vff[1]))

        if self.hard:
            self._release(t, c, v_in)
        lo0, hi0, lo1, hi1 = self._windows(dt)
        self._follow(0, c[0], v_in[0], lo0, hi0, dt)
        self._follow(1, c[1], v_in[1], lo1, hi1, dt)

        self.clock += dt
        if self.clock >= self.monitor_period - 1e-12:
            self.clock = 0.0
            self._monitor(t, c, as_float(inputs["ref_pos"]), as_float(inputs["lim_pos"]))
        return self._publish()

    def _absurd(self, cmd: tuple[float, float], vff: tuple[float, float], inputs: Mapping[str, object],
                dt: float) -> str | None:
        names = _INPUT_NAMES
        fastest = self.max_speed * (1 + 1e-9)
        # the common case in one test (false for NaN and infinities too); the first offender named below
        if not (abs(cmd[0]) <= POSITION_LIMIT and abs(cmd[1]) <= POSITION_LIMIT and abs(vff[0]) <= fastest
                and abs(vff[1]) <= fastest):
            for axis in (0, 1):
                if not math.isfinite(cmd[axis]):
                    return f"input {names[axis][0]} = {cmd[axis]!r}: must be finite"
                if not math.isfinite(vff[axis]):
                    return f"input {names[axis][1]} = {vff[axis]!r}: must be finite"
                if abs(cmd[axis]) > POSITION_LIMIT:
                    return (f"input {names[axis][0]} = {cmd[axis]!r}: beyond {POSITION_LIMIT:g} mm, no axis is "
                            "that long")
                if abs(vff[axis]) > fastest:
                    return f"input {names[axis][1]} = {vff[axis]!r}: faster than max_speed = {self.max_speed:g} mm/s"
        bad = self._feedback.check(inputs, dt)
        if bad:
            return bad
        reach = self.max_speed * dt + 1e-9
        prev, self._prev_in = self._prev_in, (float(cmd[0]), float(cmd[1]))
        jump = self._jump
        if not (jump[0] or jump[1]) and (prev is None or (abs(cmd[0] - prev[0]) <= reach
                                                          and abs(cmd[1] - prev[1]) <= reach)):
            return None        # no jump latched, none new: the common case, without the loops below
        for axis in (0, 1):
            # A jump latches until the input is back within one step of the gated output.
            if self._jump[axis] and abs(cmd[axis] - self.pos[axis]) <= reach:
                self._jump[axis] = False
            elif prev is not None and abs(cmd[axis] - prev[axis]) > reach and abs(cmd[axis] - self.pos[axis]) > reach:
                self._jump[axis] = True
                self._jump_text[axis] = (f"input {names[axis][0]} jumped {prev[axis]!r} -> {cmd[axis]!r} in one step: "
                                         f"more than max_speed * dt = {reach:.4g} mm; holding until it returns to "
                                         f"the axis ({self.pos[axis]:.4f})")
        for axis in (0, 1):
            if self._jump[axis]:
                return self._jump_text[axis]
        return None

    def _brake(self, axis: int, dt: float) -> None:
        """Controlled stop of one axis: decelerate at ``decel`` to rest."""
        v = self.vel[axis]
        a_dt = self.decel * dt
        v_new = max(v - a_dt, 0.0) if v > 0 else min(v + a_dt, 0.0)
        self.pos[axis] += 0.5 * (v + v_new) * dt
        self.vel[axis] = v_new
        if self.passing[axis]:
            self._rejoin_speed[axis] = abs(v)
            self.passing[axis] = False

    def _follow(self, axis: int, c: float, v_in: float, lo: float, hi: float, dt: float) -> None:
        """Pass the input at once, or govern: rejoin it without a jump, never leaving the velocity window."""
        p, v = self.pos[axis], self.vel[axis]
        a_dt = self.decel * dt
        gap = c - p
        # An interpolator's step may exceed vff*dt by half an acceleration step, and its last step before
        # it stops carries vff 0: that is motion, pass it.
        speed, speed_in = abs(v), abs(v_in)
        consistent = abs(gap) <= ((speed if speed > speed_in else speed_in) + a_dt) * dt + 1e-9  # max(), inline
        allowed = lo - 1e-9 <= v_in <= hi + 1e-9 and lo * dt - 1e-9 <= gap <= hi * dt + 1e-9
        # Pass: while passing, or from rest when the input starts from where the output stands (a
        # back-out after a block: the input's own motion, which it accelerates itself) -- but never a
        # velocity step beyond decel * dt: an input's own step (or its rounding) is governed like any other.
        if consistent and allowed and abs(v_in - v) <= a_dt + 1e-9 and (self.passing[axis] or v == 0.0):
            self.pos[axis], self.vel[axis] = c, v_in
            self.passing[axis] = True
            return
        # Governed from here. The rejoin never goes faster than the input has asked for since the axis stopped
        # passing (nor than the axis was moving then): catching up by outrunning the input would cross the next
        # boundary faster than the program's feed, beyond overshoot_bound of that feed. Behind a moving input it
        # therefore trails it, on the side it came from, until the input slows. An input that has not moved
        # (a start away from it) is rejoined at up to max_speed, as the windows allow.
        if self.passing[axis]:
            self._rejoin_speed[axis] = speed
            self.passing[axis] = False
        cap = self._rejoin_speed[axis]
        if speed_in > cap:
            cap = self._rejoin_speed[axis] = speed_in
        # Rejoin in the input's frame: close the gap as fast as still lets the relative speed reach 0 at it.
        w = v - v_in
        direction = 1.0 if gap > 0 else -1.0
        w_target = direction * stop_speed(abs(gap), direction * w, self.decel, dt)
        v_new = v_in + min(max(w_target, w - a_dt), w + a_dt)
        v_new = min(max(v_new, lo), hi)
        if cap > 0.0:
            v_new = min(max(v_new, -cap), cap)
        v_new = min(max(v_new, v - a_dt), v + a_dt)        # never a velocity step, even when braking
        p_new = p + 0.5 * (v + v_new) * dt
        # rejoined when taking the input's (c, v_in) now is itself a step within decel
        if (abs(v_in - v) <= a_dt + 1e-9 and abs(c - p - 0.5 * (v + v_in) * dt) <= a_dt * dt + 1e-9
                and lo - 1e-9 <= v_in <= hi + 1e-9):
            p_new, v_new = c, v_in                          # rejoined: pass from here on
            self.passing[axis] = True
        self.pos[axis], self.vel[axis] = p_new, v_new

    def _release(self, t: float, c: tuple[float, float], v_in: tuple[float, float]) -> None:
        """Free a hard-blocked direction once a step that way from the present position stays inside.

        It is freed either by backing out (a move against it, as in the seed) or because the other axis
        moved so that this direction is allowed again (the wheel retracted, the table may travel).
        """
        freed = 0
        ref_out, lim_out = self.pos
        for bit, axis in ((REF_PLUS, 0), (REF_MINUS, 0), (LIM_PLUS, 1), (LIM_MINUS, 1)):
            if not self.hard & bit:
                continue
            sign = 1.0 if bit in (REF_PLUS, LIM_PLUS) else -1.0
            # probe as far as the axis could go in one monitor period at the speed it was blocked at (or
            # is now asked for); speeds are bounded by max_speed, so the probe is too
            speed = min(max(abs(v_in[axis]), self._block_speed[bit]), self.max_speed)
            probe = sign * max(speed * self.monitor_period, 1e-6)
            # An input that is itself inside asks only as far as itself: probe no farther than it (a back-out
            # that stops just inside the boundary is released, not held for ever).
            ahead = sign * (c[axis] - self.pos[axis])
            if self.inside(*c):
                if ahead <= 0.0:
                    probe = 0.0
                else:
                    probe = sign * min(abs(probe), ahead)
            ref, lim = (ref_out + probe, lim_out) if axis == 0 else (ref_out, lim_out + probe)
            if self.inside(ref_out, lim_out) and self.inside(ref, lim):
                freed |= bit
        if freed:
            self.hard &= ~freed
            self.say("info", f"t = {t:.4f} s: inside the envelope again; releasing {_mask_text(freed)}")
            self._update_alarm()

    def _monitor(self, t: float, c: tuple[float, float], ref_pos: float, lim_pos: float) -> None:
        ref_out, lim_out = self.pos
        dir_ref = _sign(ref_out - self._tick[0]) or _sign(c[0] - ref_out)
        dir_lim = _sign(lim_out - self._tick[1]) or _sign(c[1] - lim_out)
        points = [(ref_out, lim_out)]
        if self.use_actual:
            points.append((ref_pos, lim_pos))
        new = 0
        for ref, lim in points:
            new |= self._violations(ref, lim, self._tick[0], dir_ref, dir_lim)
        self.region = self._region(ref_out)
        if new & ~self.hard:
            for bit, axis in ((REF_PLUS, 0), (REF_MINUS, 0), (LIM_PLUS, 1), (LIM_MINUS, 1)):
                if new & bit & ~self.hard:
                    self._block_speed[bit] = min(abs(self.vel[axis]), self.max_speed)
            self.say("warning", f"t = {t:.4f} s: envelope violated in region {self.region} "
                                f"(ref {ref_out:.4f}, lim {lim_out:.4f}); stopping {_mask_text(new)}")
        self.hard |= new
        if self.predictive:
            # The governor keeps the output inside; say so when the input itself asks to leave.
            soft = 0
            if not self.inside(*c):
                soft = self._violations(c[0], c[1], ref_out, _sign(c[0] - ref_out), _sign(c[1] - lim_out))
            if soft & ~self.soft:
                self.say("warning", f"t = {t:.4f} s: command (ref {c[0]:.4f}, lim {c[1]:.4f}) outside the envelope "
                                    f"in region {self._region(c[0])}; holding {_mask_text(soft)} at the "
                                    "boundary")
            elif self.soft and not soft:
                self.say("info", f"t = {t:.4f} s: command inside the envelope again; following it")
            self.soft = soft
        self._update_alarm()
        self._tick = list(self.pos)

    def _update_alarm(self) -> None:
        self.blocked = self.hard | self.soft
        self.alarm = bool(self.blocked) or self.fault is not None

    def _publish(self) -> dict[str, object]:
        out = self._outputs
        out["ref_cmd"], out["lim_cmd"] = self.pos
        out["ref_vff"], out["lim_vff"] = self.vel
        # the status changes at a region's boundary or an alarm: written into ``out`` when it did, and always into
        # another ``out`` (a reset's, a restored state's)
        status = (self.alarm, self.region, self.blocked)
        if self._status_of is not out or status != self._status:
            out["alarm"], out["region"], out["blocked"] = status
            self._status, self._status_of = status, out
        return out

    def check_state(self, inputs: Mapping[str, object]) -> str | None:
        """A restored state: gated commands within reach and published, speeds within max_speed, the blocked
        directions those of the hard and soft blocks, the region that of the last monitor tick."""
        why = super().check_state(inputs)
        if why:
            return why
        for i in (0, 1):
            if not abs(self.pos[i]) <= POSITION_LIMIT:
                return f"pos[{i}] = {self.pos[i]!r}: beyond {POSITION_LIMIT:g} mm, no axis is that long"
            if not abs(self.vel[i]) <= self.max_speed * (1 + 1e-9):
                return f"vel[{i}] = {self.vel[i]!r}: faster than max_speed = {self.max_speed:g} mm/s"
            if not abs(self._tick[i]) <= POSITION_LIMIT:
                return f"_tick[{i}] = {self._tick[i]!r}: beyond {POSITION_LIMIT:g} mm"
        if self._prev_in is not None and not (type(self._prev_in) is tuple and len(self._prev_in) == 2 and all(
                type(x) is float and abs(x) <= POSITION_LIMIT for x in self._prev_in)):
            return f"_prev_in = {self._prev_in!r}: not a (ref, lim) command within {POSITION_LIMIT:g} mm"
        if not (0 <= self.hard <= 15 and 0 <= self.soft <= 15 and self.blocked == self.hard | self.soft):
            return f"blocked = {self.blocked!r}: not hard {self.hard!r} | soft {self.soft!r} (directions 0..15)"
        if not all(0.0 <= v <= self.max_speed for v in self._block_speed.values()):
            return f"_block_speed = {self._block_speed!r}: not speeds within max_speed"
        if not all(0.0 <= v <= self.max_speed * (1 + 1e-9) for v in self._rejoin_speed):
            return f"_rejoin_speed = {self._rejoin_speed!r}: not speeds within max_speed"
        if self.region != find_region(self.ref_max, self._tick[0]):
            return f"region = {self.region!r}: not the region of the last tick at ref {self._tick[0]!r}"
        if not 0.0 <= self.clock <= self.monitor_period:
            return f"clock = {self.clock!r}: not within the monitor period {self.monitor_period:g} s"
        if self.fault is not None and type(self.fault) is not str:
            return f"fault = {self.fault!r}: not a message"
        return self.outputs_fault()


#: (command, feed-forward) input names of the reference and the limited axis.
_INPUT_NAMES = (("ref_cmd_in", "ref_vff_in"), ("lim_cmd_in", "lim_vff_in"))


def _sign(x: float) -> int:
    return (x > 1e-12) - (x < -1e-12)


def _mask_text(mask: int) -> str:
    names = [(REF_PLUS, "ref+"), (REF_MINUS, "ref-"), (LIM_PLUS, "lim+"), (LIM_MINUS, "lim-")]
    return ", ".join(n for bit, n in names if mask & bit) or "nothing"
