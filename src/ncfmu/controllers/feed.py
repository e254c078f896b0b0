"""Grinding-machine programmable feed control (seed: JP S60-43522).

A program store read by a program counter. Each word is one of::

    X+D3F7      feed axis X (or Y) by amount D3 in direction + at rate F7
    X+D1F2S4    the same as a wheel-wear compensation: its pulses bypass the return counter
    XF7S1       return X to the feed origin at F7, by the return counter (either side of it)
    T1          dwell T1 (spark-out: no motion)
    M2          auxiliary function M2: output m_active = 2, wait for MFIN
    END         end of the cycle

Values come from separate settings (the seed's digital switches) D1..D7 (mm), F1..F7 (mm/s),
T1..T7 (s). START1 runs from ``start_address`` (M0), START2 from ``wear_address`` (M43), EMB from
``emergency_address`` (M41) at any moment, aborting whatever runs (feed, dwell, M wait, wear cycle):
the running feed decelerates to rest first, so no velocity jump reaches a servo.

The return counters accumulate every feed from the feed origin except S4 moves; so after a
wear compensation the origin (the feed start point) has moved with the wheel, and S1 returns to it.

At the edges, as a control does:

- Stops are controlled: an alarm (``alarm_in``, an excess following error, a bad input), EMB and feed
  hold decelerate the running feed at ``accel``; a command never steps its velocity.
- A start (START1 or START2) while the wheel is away from the feed origin -- a return counter not 0,
  after an alarm stopped a cycle -- never feeds toward the work first: the start first returns every
  such axis to the feed origin (X, the infeed, before Y), at ``return_rate``, then runs the cycle
  from its entry address. The log says so.
- The M/MFIN handshake: an M word raises ``m_active`` only once MFIN is low, then waits for MFIN's
  rising edge; ``m_active`` drops to 0 when answered, so every M word has its own MFIN.
- Feed hold stops feeds (decelerating) and pauses a dwell; feed override (0..1.5, clamped with one
  log line) scales the rate of every feed word, F7 included. S1 returns -- the emergency cycle and the
  return before a restart -- run at their own rate whatever the dial says, and EMB ignores feed hold:
  an emergency return is not slowed by the operator's dial.
- ``alarm_in`` is honoured in every state: it stops a cycle, a dwell or an M wait; during the
  emergency return it latches the alarm but the return goes on (it is the back-out the limiter lets
  through).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..errors import ConfigError, ProgramError, require
from ..ports import boolean, integer, real, string
from .base import as_float, int_param, real_param, servo_ports
from .cycle import Button, CycleController, cycle_ports
from .gcode import program_lines
from .motion import LinearMove
from .mypyc_compat import mypyc_attr

#: The program store as the FMU starts: empty cycles, and an emergency return of X at F7 (a system or a
#: host loads its own program, e.g. the seed's Table 1 in ``ncfmu.systems.grinder``).
EMPTY_PROGRAM = "M0: END; M41: XF7S1; M42: END; M43: END"
#: Digital switches as the FMU starts: nothing set (0) but the rapid rate F7 of the emergency return.
SETTINGS = {"D": (0.0,) * 7, "F": (0.0,) * 6 + (10.0,), "T": (0.0,) * 7}

IDLE, RUN, EMERGENCY = 0, 1, 2
#: A return counter within this of 0 is at the feed origin (mm): float sums of D settings leave ~1e-15.
RC_ZERO = 1e-6
#: Time left of a dwell below which it is over (s): steps of dt do not sum exactly to T.
DWELL_EPS = 1e-9


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass(frozen=True)
class Word:
    """One decoded control word."""

    kind: str                    # "feed", "return", "dwell", "aux", "end"
    text: str
    line: int
    axis: str = ""               # "x" or "y"
    sign: int = 0                # +1 / -1 for feed words
    d: int = 0                   # D index 1..7
    f: int = 0                   # F index 1..7
    t: int = 0                   # T index 1..7
    m: int = 0                   # M function 1..7
    wear: bool = False           # S4


_LINE = re.compile(r"^\s*M(?P<addr>[0-9]+)\s*:\s*(?P<word>.*?)\s*$")
_FEED = re.compile(r"(?P<axis>[XY])(?P<sign>[+-]?)(?P<rest>.*)$")
_CODE = re.compile(r"([DFST])([0-9])")


def parse_program(text: str) -> dict[int, Word]:
    """Parse ``ADDRESS: WORD`` lines (newline or ``;`` separated); raise :class:`ProgramError`."""
    program: dict[int, Word] = {}
    lines = [seg for raw in program_lines(text) for seg in raw.split(";")]
    for n, raw in enumerate(lines, start=1):
        if not raw.strip() or raw.strip().startswith("#"):
            continue
        m = _LINE.match(raw)
        if not m:
            raise ProgramError(n, len(raw) - len(raw.lstrip()) + 1, raw.strip(),
                               "expected 'M<address>: <word>' (e.g. 'M0: X+D3F7')")
        addr, word = int(m.group("addr")), m.group("word").upper()
        col = m.start("word") + 1
        if addr in program:
            raise ProgramError(n, m.start("addr"), raw.strip(), f"address M{addr} given twice "
                                                               f"(first on line {program[addr].line})")
        program[addr] = _parse_word(word, n, col, raw.strip())
    return program


def _parse_word(word: str, n: int, col: int, raw: str) -> Word:
    if word == "END":
        return Word("end", word, n)
    if re.fullmatch(r"T[1-7]", word):
        return Word("dwell", word, n, t=int(word[1]))
    if re.fullmatch(r"M[1-7]", word):
        return Word("aux", word, n, m=int(word[1]))
    fm = _FEED.fullmatch(word)
    if not fm or not word:
        raise ProgramError(n, col, raw, f"unknown word {word!r} (X/Y feed, T1..T7, M1..M7 or END)")
    rest, pos = fm.group("rest"), col + fm.start("rest")
    codes: dict[str, int] = {}
    i = 0
    while i < len(rest):
        cm = _CODE.match(rest, i)
        if not cm:
            raise ProgramError(n, pos + i, raw, f"unknown code {rest[i:i + 2]!r} in {word!r} (D1..D7, F1..F7, S1, S4)")
        letter, digit = cm.group(1), int(cm.group(2))
        if letter in codes:
            raise ProgramError(n, pos + i, raw, f"{letter} given twice in {word!r}")
        if letter in "DFT" and not 1 <= digit <= 7:
            raise ProgramError(n, pos + i, raw, f"{letter}{digit}: settings are numbered 1..7")
        if letter == "T":
            raise ProgramError(n, pos + i, raw, "a dwell T is a word of its own")
        codes[letter] = digit
        i = cm.end()
    axis, sign = fm.group("axis").lower(), {"+": 1, "-": -1, "": 0}[fm.group("sign")]
    if "F" not in codes:
        raise ProgramError(n, col + len(word), raw, f"missing rate: {word!r} needs F1..F7")
    s = codes.get("S")
    if s is not None and s not in (1, 4):
        raise ProgramError(n, col, raw, f"S{s} is not supported (S1 return to the feed origin, S4 wear compensation)")
    if s == 1:
        if "D" in codes or sign:
            raise ProgramError(n, col, raw, "S1 takes no direction and no D: the return counter gives both")
        return Word("return", word, n, axis=axis, f=codes["F"])
    if "D" not in codes:
        raise ProgramError(n, col + len(word), raw, f"missing amount: {word!r} needs D1..D7 (or S1)")
    if not sign:
        raise ProgramError(n, col + 1, raw, f"missing direction: {word!r} needs + or -")
    return Word("feed", word, n, axis=axis, sign=sign, d=codes["D"], f=codes["F"], wear=s == 4)


def _setting_ports():
    ports = []
    for letter, unit, what in (("D", "mm", "feed amount"), ("F", "mm/s", "feed rate"), ("T", "s", "dwell time")):
        for k in range(1, 8):
            ports.append(real(f"{letter}{k}", "parameter", SETTINGS[letter][k - 1], unit,
                              f"{what} {letter}{k} (digital switch; 0: not set)", min=0.0))
    return tuple(ports)


@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)
class ProgrammableFeed(CycleController):
    MODEL_NAME = "ProgrammableFeed"
    DESCRIPTION = ("Grinding-machine programmable feed control: program store, rough/fine/spark-out, wheel-wear "
                   "compensation, emergency return to the feed origin (JP S60-43522)")
    SEED = "programmable-feed-JPS6043522.txt"
    STOP_TIME = 35.0
    AXES = ("x", "y")

    PORTS = (
        *_setting_ports(),
        # one line, ';'-separated: an XML attribute would turn newlines into spaces
        string("program", "parameter", EMPTY_PROGRAM,
               "program store: 'M<address>: <word>' separated by newlines or ';'"),
        integer("start_address", "parameter", 0, "entry of the normal cycle (START1)", min=0),
        integer("wear_address", "parameter", 43, "entry of the wear-compensation cycle (START2)", min=0),
        integer("emergency_address", "parameter", 41, "entry of the emergency cycle (EMB)", min=0),
        real("x_origin", "parameter", 0.0, "mm", "X feed origin (machine position at start)"),
        real("y_origin", "parameter", 0.0, "mm", "Y feed origin (machine position at start)"),
        real("accel", "parameter", 500.0, "mm/s2", "acceleration/deceleration limit of every feed", min=0.0,
             min_exclusive=True),
        real("return_rate", "parameter", 10.0, "mm/s", "rate of the return to the feed origin before a start away "
             "from it", min=0.0, min_exclusive=True),
        *cycle_ports("a feed word", "max_following_error", "inpos_timeout"),
        boolean("start", "input", False, "START1: normal cycle (rising edge)"),
        boolean("wear_start", "input", False, "START2: wheel-wear compensation cycle (rising edge)"),
        boolean("emergency", "input", False, "EMB: emergency return (rising edge), at any moment"),
        boolean("mfin", "input", False, "M-function finish from the auxiliary device"),
        boolean("alarm_in", "input", False, "external alarm (area limiter): latch alarm, decelerate to rest"),
        boolean("feed_hold", "input", False, "feed hold: feeds decelerate to rest, a dwell pauses, while true"),
        real("feed_override", "input", 1.0, "1", "feed override of every feed word (not of S1 returns)",
             min=0.0, max=1.5),
        *servo_ports(("x", 0.0), ("y", 0.0)),
        boolean("run", "output", None, "normal or wear-compensation cycle running (RUN)"),
        boolean("busy", "output", None, "a feed, dwell or M wait is executing (BUSY)"),
        boolean("emergency_active", "output", None, "emergency return cycle running"),
        integer("pc", "output", None, "program counter (address of the word executing)"),
        integer("m_active", "output", None, "auxiliary function waiting for MFIN (0 none)"),
        real("dwell_left", "output", None, "s", "time left of the present dwell"),
        real("return_counter_x", "output", None, "mm", "X feed counted from the feed origin (S4 excluded)"),
        real("return_counter_y", "output", None, "mm", "Y feed counted from the feed origin (S4 excluded)"),
        boolean("alarm", "output", None, "alarm latched (external alarm, bad input)"),
        *cycle_ports("a feed word", "inpos_band"),          # appended: the ports before keep their value references
    )

    @classmethod
    def unread(cls, values: Mapping[str, object]) -> dict[str, str]:
        """Also the D, F and T settings no word of the program names."""
        out = super().unread(values)
        try:
            words = parse_program(str(values.get("program", EMPTY_PROGRAM))).values()
        except ProgramError:            # the run refuses the program, naming line and column
            return out
        for letter, index in (("D", "d"), ("F", "f"), ("T", "t")):
            used = sorted({getattr(w, index) for w in words} - {0})
            for k in range(1, 8):
                if k not in used:
                    out[f"{letter}{k}"] = (f"reads {', '.join(f'{letter}{i}' for i in used) or f'no {letter} setting'}"
                                           f"{' only' if used else ''} (the {letter} settings its program names)")
        return out

    def configure(self, values: Mapping[str, object]) -> None:
        self.D = [real_param(values, f"D{k}") for k in range(1, 8)]
        self.F = [real_param(values, f"F{k}") for k in range(1, 8)]
        self.T = [real_param(values, f"T{k}") for k in range(1, 8)]
        self.program = parse_program(str(values["program"]))
        self.start_address = int_param(values, "start_address")
        self.wear_address = int_param(values, "wear_address")
        self.emergency_address = int_param(values, "emergency_address")
        self.x_origin = real_param(values, "x_origin")
        self.y_origin = real_param(values, "y_origin")
        self.accel = real_param(values, "accel")
        self.return_rate = real_param(values, "return_rate")
        self.configure_cycle(values)
        for name in ("start_address", "emergency_address", "wear_address"):
            entry = getattr(self, name)
            require(entry in self.program, name, entry, f"entry address M{entry} is missing from the program")
            self._check_reaches_end(name, entry)

    def _check_reaches_end(self, name: str, entry: int) -> None:
        pc = entry
        while True:
            word = self.program.get(pc)
            if word is None:
                raise ConfigError("program", f"M{entry}", f"the cycle from M{entry} ({name}) runs past M{pc - 1} "
                                                          "without END")
            if word.kind == "end":
                return
            self._check_settings(word, pc)
            pc += 1

    def _check_settings(self, word: Word, pc: int) -> None:
        where = f"used by M{pc}: {word.text} (line {word.line})"
        if word.kind in ("feed", "return"):
            require(self.F[word.f - 1] > 0, f"F{word.f}", self.F[word.f - 1], f"must be > 0: {where}")
        if word.kind == "feed":
            require(self.D[word.d - 1] > 0, f"D{word.d}", self.D[word.d - 1], f"is not set (0): {where}")
        if word.kind == "dwell":
            require(self.T[word.t - 1] > 0, f"T{word.t}", self.T[word.t - 1], f"is not set (0): {where}")

    # -- state ----------------------------------------------------------------------------------
    def reset(self) -> None:
        self.mode = IDLE
        self.pc = 0
        self.word: Word | None = None
        self.busy = False
        self.m_active = 0
        self.dwell_left = 0.0
        self.rc = {"x": 0.0, "y": 0.0}                    # return counters
        self.cmd = {"x": self.x_origin, "y": self.y_origin}
        self.vff = {"x": 0.0, "y": 0.0}
        self.reset_cycle()
        self.move = LinearMove(self.accel)
        self.move.begin((self.x_origin, self.y_origin), (self.x_origin, self.y_origin), 1.0)
        self._counting = True                              # gate 55: closed during S4
        self._pending_emergency = False
        self._wear_button, self._emergency_button = Button(), Button()
        self._mfin_was = False
        self._mfin_stuck_said = False
        self._then = 0                                     # entry address after the return to the origin
        self._outputs: dict[str, object] = {}
        self._publish()

    # -- the cycle ------------------------------------------------------------------------------
    def _load(self, address: int) -> None:
        """Read the word at ``address`` (the seed's CL1..CL5 read cycle) and start executing it."""
        self.pc = address
        word = self.word = self.program[address]
        self.busy = True
        self.inpos.reset()
        here = (self.cmd["x"], self.cmd["y"])
        if word.kind == "feed":
            delta = word.sign * self.D[word.d - 1]
            self._start_move(word.axis, delta, self.F[word.f - 1], counting=not word.wear)
        elif word.kind == "return":
            self._start_move(word.axis, -self.rc[word.axis], self.F[word.f - 1], counting=True)
        elif word.kind == "dwell":
            self.dwell_left = self.T[word.t - 1]
        elif word.kind == "aux":
            self.m_active = 0                              # raised once MFIN is low (step)
            self._mfin_stuck_said = False
        else:  # END
            self.busy = False
            self.word = None
            self.mode = IDLE
            self.move.begin(here, here, 1.0)

    def _start_move(self, axis: str, delta: float, rate: float, counting: bool) -> None:
        start = (self.cmd["x"], self.cmd["y"])
        end = (start[0] + delta, start[1]) if axis == "x" else (start[0], start[1] + delta)
        self._counting = counting
        self.move.begin(start, end, rate)

    def _word_done(self, word: Word, inputs: Mapping[str, object], arrived: bool) -> bool:
        if word.kind in ("feed", "return"):
            return arrived
        if word.kind == "dwell":
            return self.dwell_left == 0.0
        if word.kind == "aux":
            # its own MFIN: a rising edge after the strobe went up
            return self.m_active != 0 and bool(inputs["mfin"]) and not self._mfin_was
        return True

    def away_from_origin(self) -> list[str]:
        """Axes whose return counter is not 0: the wheel is not at the feed origin there (X first)."""
        return [a for a in ("x", "y") if abs(self.rc[a]) > RC_ZERO]

    def _start(self, t: float, entry: int) -> None:
        self.mode = RUN
        away = self.away_from_origin()
        if away:
            # Never feed toward the work from where an alarm left the wheel: back to the origin first.
            self.say("warning", f"t = {t:.4f} s: start away from the feed origin (return counters "
                                f"{', '.join(f'{a.upper()} {self.rc[a]:+.4f} mm' for a in away)}); returning to "
                                f"the origin at {self.return_rate:g} mm/s before M{entry}")
            self._then = entry
            self._return_first(away[0])
        else:
            self._load(entry)

    def _return_first(self, axis: str) -> None:
        self.word = Word("return", f"{axis.upper()} to the feed origin", 0, axis=axis)
        self.busy = True
        self.inpos.reset()
        self._start_move(axis, -self.rc[axis], self.return_rate, counting=True)

    # -- the hooks of the NC cycle (controllers/cycle.py owns the order of a step) -----------------
    STOP_SAYS = "feed decelerating to rest, cycle stopped"
    MOTION_SAYS = "the feed is"
    FOLLOW_UP_PER_AXIS = True            # each axis its own feed and return counter

    def read_buttons(self, inputs: Mapping[str, object]) -> tuple[bool, bool, bool]:
        """START1, START2 and EMB."""
        return (self.start_button.pressed(inputs["start"]), self._wear_button.pressed(inputs["wear_start"]),
                self._emergency_button.pressed(inputs["emergency"]))

    def halt(self) -> None:
        """The running feed decelerates to rest; a dwell or M wait is abandoned."""
        self.move.halt()
        self.mode, self.busy, self.word, self.m_active, self.dwell_left = IDLE, False, None, 0, 0.0
        self._pending_emergency = False

    def idle(self) -> bool:
        return self.mode == IDLE

    def watching_following_error(self) -> bool:
        return self.mode != IDLE and not self._pending_emergency      # why: in CycleController

    def external_alarm(self, t: float) -> None:
        """``alarm_in`` is honoured in every state; the emergency return goes on (it is the back-out the limiter
        lets through), and at rest it latches without a stop to make."""
        if self.mode == EMERGENCY:
            self.latch_alarm(t, "alarm_in (area limiter) is set during the emergency return",
                             "alarm latched, the return goes on")
        elif self.mode != IDLE or self.word is not None or self._pending_emergency:
            super().external_alarm(t)
        else:
            self.alarm = True

    def command_point(self) -> list[float]:
        return [self.cmd["x"], self.cmd["y"]]

    def follow_up(self, t: float, inputs: Mapping[str, object]) -> None:
        self._advance_move_outputs()                      # the commands where the feed stands now
        super().follow_up(t, inputs)

    def rebase(self, actual: Mapping[str, float]) -> None:
        """The return counters follow: they count where the wheel really is from the feed origin, so S1 and the
        return before a restart go to the true origin."""
        for axis, pos in actual.items():
            if self._counting:                     # an S4 move is not counted: nor is what it fell short
                self.rc[axis] += pos - self.cmd[axis]
            self.cmd[axis] = pos
        here = (self.cmd["x"], self.cmd["y"])
        self.move.begin(here, here, 1.0)
        self.vff["x"] = self.vff["y"] = 0.0

    def take_commands(self, t: float, inputs: Mapping[str, object], edges: Any, bad: str | None,
                      why: str | None) -> None:
        start, wear, emb = edges
        if emb and not bad:
            # EMB: abort whatever runs; a running feed first decelerates to rest (EMB.SDW).
            self.say("warning", f"t = {t:.4f} s: EMB: emergency return from M{self.emergency_address}")
            self.alarm = bool(inputs["alarm_in"])
            self.mode, self.m_active, self.dwell_left = EMERGENCY, 0, 0.0
            self._pending_emergency = True
            self.move.halt()
            self.word = None
        elif start or wear:
            super().take_commands(t, inputs, (start, wear), bad, why)

    def begin(self, t: float, edges: Any) -> None:
        start, _ = edges
        self._start(t, self.start_address if start else self.wear_address)

    def advance(self, t: float, dt: float, inputs: Mapping[str, object], why: str | None) -> None:
        hold = bool(inputs["feed_hold"]) and self.mode != EMERGENCY
        if self._pending_emergency:
            self.move.advance(dt, 0.0)                     # decelerate the aborted feed
            if self.move.done:
                self._pending_emergency = False
                self.follow_up(t, inputs)                  # (from where the feed stands now)
                self._load(self.emergency_address)
        elif self.word is not None:
            word = self.word
            if word.kind == "feed":
                rate = self.override.read(self, t, as_float(inputs["feed_override"]))
                self.move.advance(dt, 0.0 if hold else rate)
            elif word.kind == "return":
                self.move.advance(dt, 0.0 if hold else 1.0)
            elif word.kind == "dwell" and not hold:
                left = self.dwell_left - dt
                self.dwell_left = left if left > DWELL_EPS else 0.0
            elif word.kind == "aux" and self.m_active == 0 and not inputs["mfin"]:
                self.m_active = word.m                     # strobe: the previous answer has dropped
            elif word.kind == "aux" and self.m_active == 0 and not self._mfin_stuck_said:
                self._mfin_stuck_said = True
                self.say("warning", f"t = {t:.4f} s: M{word.m} (M{self.pc}) waits for MFIN to drop: it is still "
                                    "high (the auxiliary device has not released the previous answer)")
            # a feed word ends when its axis stands at this controller's own command (the cycle's in-position check)
            arrived = (word.kind in ("feed", "return")
                       and self.arrival(t, dt, self.move.done, inputs, (word.axis,)))
            if self._word_done(word, inputs, arrived):
                if word.kind == "aux":
                    self.m_active = 0
                self._advance_move_outputs()
                self._next_word()
        elif not self.move.done:
            self.move.advance(dt, 0.0)                     # the controlled stop after an alarm
        self._mfin_was = bool(inputs["mfin"])
        self._advance_move_outputs()

    def _next_word(self) -> None:
        if self.word is not None and self.word.line == 0:  # a return before the start: next axis, then the entry
            away = self.away_from_origin()
            if away:
                self._return_first(away[0])
            else:
                self._load(self._then)
        else:
            self._load(self.pc + 1)

    def _advance_move_outputs(self) -> None:
        """Copy the interpolator's position to the commands; count the feed in the return counters."""
        x, y = self.move.position()
        if self._counting:
            self.rc["x"] += x - self.cmd["x"]
            self.rc["y"] += y - self.cmd["y"]
        self.cmd["x"], self.cmd["y"] = x, y
        vx, vy = self.move.velocity()
        self.vff["x"], self.vff["y"] = vx, vy

    def _publish(self) -> dict[str, object]:
        out = self._outputs
        out["x_cmd"], out["y_cmd"] = self.cmd["x"], self.cmd["y"]
        out["x_vff"], out["y_vff"] = self.vff["x"], self.vff["y"]
        out["run"] = self.mode == RUN
        out["busy"] = self.busy and self.word is not None
        out["emergency_active"] = self.mode == EMERGENCY
        out["pc"] = self.pc
        out["m_active"] = self.m_active
        out["dwell_left"] = self.dwell_left
        out["return_counter_x"], out["return_counter_y"] = self.rc["x"], self.rc["y"]
        out["alarm"] = self.alarm
        return out

    def check_state(self, inputs: Mapping[str, object]) -> str | None:
        """A restored state: the word executing is the program's at the program counter (or the return to the
        origin before a start), the command where the interpolator stands and, while a cycle runs, within
        max_following_error (and one step) of the actual axes."""
        from .base import POSITION_LIMIT  # here: this check is one self-contained piece
        why = super().check_state(inputs)
        if why:
            return why
        why = self.move_fault(self.move, self.accel, {1.0, self.return_rate, *self.F})
        if why:
            return why
        if self.mode not in (IDLE, RUN, EMERGENCY):
            return f"mode = {self.mode!r}: not idle, run or emergency"
        for name in ("pc", "_then"):
            if getattr(self, name) not in self.program and getattr(self, name) != 0:
                return f"{name} = {getattr(self, name)!r}: no address of the program"
        word = self.word
        if word is not None:
            axis = word.axis.upper()
            if not (word == self.program.get(self.pc)
                    or (word.line == 0 and word.axis in ("x", "y")
                        and word == Word("return", f"{axis} to the feed origin", 0, axis=word.axis))):
                return f"word = {word!r}: not the word at M{self.pc} of the program"
        if self.m_active and (word is None or word.kind != "aux" or word.m != self.m_active):
            return f"m_active = {self.m_active!r}: not the M word executing"
        if not 0.0 <= self.dwell_left <= max(self.T):
            return f"dwell_left = {self.dwell_left!r}: not within the dwell settings T"
        for a in ("x", "y"):
            if not abs(self.cmd[a] - self.rc[a]) <= POSITION_LIMIT:
                return f"rc[{a!r}] = {self.rc[a]!r}: puts the feed origin beyond {POSITION_LIMIT:g} mm"
        if (self.cmd["x"], self.cmd["y"]) != self.move.position():
            return f"cmd = {self.cmd!r}: not where the interpolator stands ({self.move.position()!r})"
        if (self.vff["x"], self.vff["y"]) not in (self.move.velocity(), (0.0, 0.0)):
            return f"vff = {self.vff!r}: not the interpolator's velocity"
        if self.mode != IDLE and not self.alarm and not self._pending_emergency:
            why = self.reach_fault(inputs, self.cmd)
            if why:
                return why
        return self.outputs_fault()
