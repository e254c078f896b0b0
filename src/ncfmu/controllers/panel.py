"""Operator panel and auxiliary devices, so that every system runs unchanged in any FMI tool.

Push buttons are pressed at parameterised times (a pulse of ``pulse`` seconds); START can be
pressed a second time (``restart_at``), so a restart after an alarm is scriptable in an SSP. The
M-function finish signal MFIN answers every M word with its own pulse: it rises ``mfin_delay``
seconds after that M word appeared on ``m_active`` and falls when ``m_active`` drops (or changes to
another M word, whose delay then starts afresh), as the auxiliary device would. A negative time
means "never".
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import ClassVar

from ..errors import ConfigError
from ..ports import boolean, integer, real
from .base import Controller, real_param
from .mypyc_compat import mypyc_attr


@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)
class OperatorPanel(Controller):
    MODEL_NAME = "OperatorPanel"
    DESCRIPTION = ("Operator panel: cycle start, wear-compensation start, emergency, feed hold at given times; "
                   "MFIN after a delay")
    SEED = "programmable-feed-JPS6043522.txt"
    STOP_TIME = 10.0
    # The button times and dials are tunable: a run can branch from a saved state with other times.
    # The schedule's event times and the quiet interval of the buttons published last (_publish): derived from the
    # parameters and this object's own publishing, so not saved in a state -- a restored panel keeps a fresh
    # panel's, which reset() leaves empty (its first step publishes in full).
    DERIVED: ClassVar[tuple[str, ...]] = ("_events", "_quiet_from", "_quiet_until")

    PORTS = (
        real("start_at", "parameter", 0.1, "s", "time of the cycle-start push (START1); negative: never",
             variability="tunable"),
        real("restart_at", "parameter", -1.0, "s", "time of a second cycle-start push (a restart, e.g. after an "
             "alarm); negative: never", variability="tunable"),
        real("wear_start_at", "parameter", -1.0, "s",
             "time of the wear-compensation start push (START2); negative: never", variability="tunable"),
        real("emergency_at", "parameter", -1.0, "s", "time of the emergency push (EMB); negative: never",
             variability="tunable"),
        real("hold_at", "parameter", -1.0, "s", "feed hold pressed at this time; negative: never",
             variability="tunable"),
        real("release_at", "parameter", -1.0, "s", "feed hold released at this time; negative: never",
             variability="tunable"),
        real("pulse", "parameter", 0.01, "s", "length of a push-button pulse", min=0.0, min_exclusive=True),
        real("mfin_delay", "parameter", 0.5, "s", "delay of the auxiliary device's MFIN after an M word",
             min=0.0, variability="tunable"),
        real("override", "parameter", 1.0, "1", "feed override dial", min=0.0, max=1.5, variability="tunable"),
        integer("m_active", "input", 0, "active M function number (0 none), from the controller"),
        boolean("start", "output", None, "cycle start push button (START1)"),
        boolean("wear_start", "output", None, "wear-compensation start push button (START2)"),
        boolean("emergency", "output", None, "emergency push button (EMB)"),
        boolean("feed_hold", "output", None, "feed hold switch"),
        boolean("mfin", "output", None, "M-function finish from the auxiliary device"),
        real("feed_override", "output", None, "1", "feed override dial"),
        # appended: the ports before keep their value references
        real("repeat_every", "parameter", -1.0, "s", "the button times repeat with this period (a shift of "
             "cycles: START, wear start, ... again every period); negative: once", variability="tunable"),
    )

    # Each time, dial and delay drives one output (pulse: the push buttons): a system that does not connect
    # that output cannot feel the setting (ncfmu warns about a --set of it).
    ACTS_ON = {"start_at": ("start",), "restart_at": ("start",), "wear_start_at": ("wear_start",),
               "emergency_at": ("emergency",), "hold_at": ("feed_hold",), "release_at": ("feed_hold",),
               "pulse": ("start", "wear_start", "emergency"), "mfin_delay": ("mfin",),
               "override": ("feed_override",), "m_active": ("mfin",),
               "repeat_every": ("start", "wear_start", "emergency", "feed_hold")}

    def configure(self, values: Mapping[str, object]) -> None:
        self.start_at = real_param(values, "start_at")
        self.restart_at = real_param(values, "restart_at")
        self.wear_start_at = real_param(values, "wear_start_at")
        self.emergency_at = real_param(values, "emergency_at")
        self.hold_at = real_param(values, "hold_at")
        self.release_at = real_param(values, "release_at")
        self.pulse = real_param(values, "pulse")
        self.mfin_delay = real_param(values, "mfin_delay")
        self.override = real_param(values, "override")
        self.repeat_every = real_param(values, "repeat_every")
        if 0.0 <= self.repeat_every <= self.pulse:
            raise ConfigError("repeat_every", self.repeat_every, f"must be negative (once) or longer than the "
                              f"pulse ({self.pulse:g} s)")
        # The times in the schedule at which a button output can change: each output is a test ``now >= e``
        # of these (written as _publish writes them, so equal to the last bit), or a combination of them.
        events: list[float] = []
        for at in (self.start_at, self.restart_at, self.wear_start_at, self.emergency_at):
            if at >= 0.0:
                events += [at - 1e-9, at + self.pulse - 1e-9]
        if self.hold_at >= 0.0:
            events.append(self.hold_at - 1e-9)
        if self.release_at >= 0.0 and self.release_at > self.hold_at:
            events.append(self.release_at - 1e-9)
        self._events = sorted(events)
        self._forget()          # a retune (a time, the dial) publishes in full at the next step

    def reset(self) -> None:
        self.clock = 0.0            # panel time, advanced only by dt
        self.m_seen_for = 0.0       # how long the present M word has been active
        self.m_seen = 0             # which M word that is
        self._outputs: dict[str, object] = {}
        self._publish(0)
        self._forget()

    def _forget(self) -> None:
        """No quiet interval: the next step publishes every output."""
        self._quiet_from, self._quiet_until = math.inf, -math.inf

    def _pressed(self, at: float, now: float) -> bool:
        # Half a step of slack so a press at k*dt is seen at that step whatever the rounding.
        return at >= 0.0 and at - 1e-9 <= now < at + self.pulse - 1e-9

    def step(self, t: float, dt: float, inputs: Mapping[str, object]) -> dict[str, object]:
        self.clock += dt
        m = int(inputs["m_active"])  # type: ignore[call-overload]
        # a new M word (also one replacing another without a 0 between) starts its own delay
        self.m_seen_for = (self.m_seen_for + dt if m == self.m_seen else dt) if m else 0.0
        self.m_seen = m
        return self._publish(m)

    def _publish(self, m: int) -> dict[str, object]:
        out = self._outputs
        # the time in the button schedule: the panel's clock, or its time into the present period
        now = self.clock % self.repeat_every if self.repeat_every > 0.0 else self.clock
        mfin = bool(m) and self.m_seen_for >= self.mfin_delay - 1e-9
        if self._quiet_from <= now < self._quiet_until:
            out["mfin"] = mfin
            return out          # no event since the last full publish: the buttons and the dial are as they were
        # the interval between events that ``now`` is in: the buttons stay as below until the schedule leaves it
        self._quiet_from, self._quiet_until = -math.inf, math.inf
        for e in self._events:
            if e <= now:
                self._quiet_from = e
            else:
                self._quiet_until = e
                break
        out["start"] = self._pressed(self.start_at, now) or self._pressed(self.restart_at, now)
        out["wear_start"] = self._pressed(self.wear_start_at, now)
        out["emergency"] = self._pressed(self.emergency_at, now)
        held = self.hold_at >= 0.0 and now >= self.hold_at - 1e-9
        released = self.release_at >= 0.0 and self.release_at > self.hold_at and now >= self.release_at - 1e-9
        out["feed_hold"] = held and not released
        out["mfin"] = mfin
        out["feed_override"] = self.override
        return out

    def check_state(self, inputs: Mapping[str, object]) -> str | None:
        """A restored state: the panel clock and the time the present M word has been active are times."""
        why = super().check_state(inputs)
        if why:
            return why
        if not self.clock >= 0.0:
            return f"clock = {self.clock!r}: must be >= 0"
        if not (0.0 <= self.m_seen_for <= self.clock + 1e-9 and (self.m_seen or self.m_seen_for == 0.0)):
            return f"m_seen_for = {self.m_seen_for!r}: not a time the M word {self.m_seen!r} can have been active"
        if not 0.0 <= self._outputs["feed_override"] <= 1.5:  # type: ignore[operator]
            return f"_outputs['feed_override'] = {self._outputs['feed_override']!r}: must be in [0, 1.5]"
        return None
