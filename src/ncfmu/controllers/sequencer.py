"""Lathe repetitive-cut sequencer (seed: US 4,017,723).

The seed's hardware, register for register:

- tape registers per block: Xf (offset of the start point STP from the stock outline), Xd (depth
  of cut per pass), Xp (X component of the cut, taper), Zp (cut length), N (passes);
- the ΣX accumulator (register 18): loaded with Xf once per block, incremented by Xd at the
  start of every pass, so pass n moves ΣX = Xf + n·Xd;
- the four-stage shift register 46 (sub-cycles SC1..SC4) and the reversible pass counter 48, which
  counts down at the SC3 -> SC4 shift;
- the X/Z distance counters 52/54: a sub-cycle ends when its commanded motion is complete AND both
  servos report in-position (the modern form of "the count reaches zero").

Axis convention: X is the radius, infeed is -X; Z runs along the spindle, cutting is -Z.

    SC1 infeed   X: x_start -> x_start - ΣX                      (rapid)
    SC2 cut      Z: -Zp, X: -Xp at the same time (taper)        (feed, override applies)
    SC3 retract  X: +ΣX                                          (rapid)
    SC4 return   Z: +Zp, X: +Xp -> back at STP                  (rapid)

Each block may set its own start point (``block[k].own_stp``; the seed: "cut another part of the
same workpiece"), else it keeps the previous block's, so one block series can rough the two
diameters of a stepped shaft. Every move to a start point -- the first, between blocks, and the
restart after an alarm -- is a safe approach: X retracts clear first (to the higher of the two
radii), then Z travels, then X comes down; never a diagonal across the work.

Stops are controlled: feed hold, ``alarm_in``, an excess following error or a bad input decelerate
the present move along its path at ``accel`` (the alarm latches at once). A sub-cycle ends only when
the sequencer's own command has reached its end AND the actual positions are within ``inpos_band``
of it AND the servos report in-position, so a move held downstream (by the area limiter) never
counts as done. After an alarm, START re-bases the command on the actual position (follow-up, as an
NC does after a stop it did not command) and approaches the start point safely.

A part program (``program``, :mod:`.lathe_program`) replaces the registers: the Fanuc 0i-T dialect (tools and
their offsets, the spindle with G96/G99 read back from ``spindle_speed``, dwells, stops, G28), whose
G71 stock removal works out the passes from the finished profile -- shoulders, tapers, radii, pockets -- and runs
each as the seed's SC1 infeed (at most U deeper), SC2 cut in -Z to the profile plus its allowances, SC3
retract by R, SC4 return in Z, then one pass along the profile shifted by the allowances, so the stock left
for G70's finishing pass is the allowance everywhere. ``line`` and ``canned_cycle`` say where the program
is; ``subcycle``, ``pass_no`` and ``sigma_x`` the pass. Feed hold, override, alarms, the in-position check
and the restart (from the program's start, after the safe approach) work as for the registers.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, ClassVar, Final

from ..errors import require
from ..ports import boolean, integer, real, string
from . import lathe_program
from .base import POSITION_LIMIT, SPEED_LIMIT, as_float, input_or, int_param, real_param, servo_ports
from .cycle import CycleController, cycle_ports
from .g7x import NO_MODAL, Segment, Tool
from .meaning import ProgramMeaning, Stock, lathe_meaning, registers_meaning
from .motion import ARC_TANGENTIAL, ElementMove, LinearMove
from .mypyc_compat import mypyc_attr

MAX_BLOCKS = 8
#: Rows of the tool table (T<tool><offset>: tool and offset 1..8).
MAX_TOOLS = 8
WORK_OFFSETS = 6            # G54..G59
#: A dwell whose time left is below this is over (s): steps of dt do not sum exactly to its time.
DWELL_EPS = 1e-9
#: tool, spindle_dir, coolant, s_cmd while no program move runs: those of no program (a constant, not read from a
#: ``Modal`` every step: its fields are a dataclass's, each read an attribute lookup).
_NO_PROGRAM_MODAL: Final[tuple[int, int, bool, float]] = (NO_MODAL.tool, NO_MODAL.spindle, NO_MODAL.coolant,
                                                          NO_MODAL.rpm(0.0))
#: A thread's Z may fall back this far (mm) as the spindle's encoder jitters; more is a spindle turning backwards.
THREAD_BACKLASH = 1e-9

IDLE, SC1, SC2, SC3, SC4 = 0, 1, 2, 3, 4
#: Phase before SC1 when the command is not at STP on start (reported as sub-cycle 0 while busy).
APPROACH = -1
#: A program's move outside a pass (reported as sub-cycle 0 while busy).
PROGRAM_MOVE = -2


#: The start point as the FMU starts: a 10 mm radius at Z 0 (a system gives its own, e.g. lathe_roughing's).
X_START, Z_START = 10.0, 0.0
#: The bar stock as the FMU starts: up to the default registers' stock outline (X_START - Xf = 9.5 mm radius),
#: its face at Z_START, 50 mm long.
STOCK_DIAMETER, STOCK_LENGTH = 19.0, 50.0


@mypyc_attr(native_class=False, allow_interpreted_subclasses=True)
@dataclass
class Block:
    """One tape block: the seed's registers Xf, Xd, Xp, Zp, N plus the block's rates. The defaults are no
    system's scenario: one pass 1 mm deep (Xf + Xd) over 10 mm."""

    Xf: float = 0.5
    Xd: float = 0.5
    Xp: float = 0.0
    Zp: float = 10.0
    N: int = 1
    feed: float = 4.0
    rapid: float = 50.0
    own_stp: bool = False
    x_stp: float = X_START
    z_stp: float = Z_START


def _block_ports():
    ports = []
    for k in range(1, MAX_BLOCKS + 1):
        b = Block()
        p = f"block[{k}]"
        ports += [
            real(f"{p}.Xf", "parameter", b.Xf, "mm", f"block {k}: offset of STP from the stock outline (register Xf)",
                 min=0.0),
            real(f"{p}.Xd", "parameter", b.Xd, "mm", f"block {k}: depth of cut per pass (register Xd)", min=0.0,
                 min_exclusive=True),
            real(f"{p}.Xp", "parameter", b.Xp, "mm",
                 f"block {k}: X component of the cut, taper (register Xp; 0 = cylinder)"),
            real(f"{p}.Zp", "parameter", b.Zp, "mm", f"block {k}: cut length (register Zp)", min=0.0,
                 min_exclusive=True),
            integer(f"{p}.N", "parameter", b.N, f"block {k}: number of passes (pass counter preset)", min=1, max=10000),
            real(f"{p}.feed", "parameter", b.feed, "mm/s", f"block {k}: cutting feed of SC2", min=0.0,
                 min_exclusive=True),
            real(f"{p}.rapid", "parameter", b.rapid, "mm/s", f"block {k}: rapid rate of SC1, SC3, SC4", min=0.0,
                 min_exclusive=True),
            boolean(f"{p}.own_stp", "parameter", b.own_stp, f"block {k}: starts from its own start point "
                    f"block[{k}].x_stp/z_stp (else the previous block's; block 1: x_start/z_start)"),
            real(f"{p}.x_stp", "parameter", b.x_stp, "mm", f"block {k}: X of its own start point (with own_stp)"),
            real(f"{p}.z_stp", "parameter", b.z_stp, "mm", f"block {k}: Z of its own start point (with own_stp)"),
        ]
    return tuple(ports)


def _tool_ports():
    ports = []
    for k in range(1, MAX_TOOLS + 1):
        p = f"tool[{k}]"
        ports += [
            real(f"{p}.x_offset", "parameter", 0.0, "mm", f"tool offset {k} (T..{k:02d}): X (radius) of the axes "
                 "with the tool's tip at the programmed X 0"),
            real(f"{p}.z_offset", "parameter", 0.0, "mm", f"tool offset {k}: Z of the axes with the tip at Z 0"),
            real(f"{p}.nose_radius", "parameter", 0.0, "mm", f"tool offset {k}: nose radius of the insert", min=0.0),
            integer(f"{p}.tip", "parameter", 0, f"tool offset {k}: imaginary tool-nose number (Fanuc's 0-9)",
                    min=0, max=9),
            real(f"{p}.max_depth", "parameter", 0.0, "mm", f"tool offset {k}: deepest cut the insert takes (0: not "
                 "given)", min=0.0),
        ]
    return tuple(ports)


def _tool_shape_ports():
    """The tool table's shapes: what the part check sweeps (read by the host's part check, not by the cycle)."""
    ports = []
    for k in range(1, MAX_TOOLS + 1):
        p = f"tool[{k}]"
        ports += [
            real(f"{p}.insert_angle", "parameter", 80.0, "deg", f"tool offset {k}: corner angle of the turning "
                 "insert (80: rhombic C, 55: D, 35: V, 60: triangular, 90: square; the part check's tool)",
                 min=0.0, min_exclusive=True, max=90.0),
            real(f"{p}.width", "parameter", 0.0, "mm", f"tool offset {k}: width of a grooving or parting blade "
                 "(0: not one; its programmed point is the corner the tip names, 3: toward the chuck)", min=0.0),
            real(f"{p}.drill_diameter", "parameter", 0.0, "mm", f"tool offset {k}: diameter of a drill on the "
                 "spindle axis, programmed at its point (0: not one)", min=0.0),
        ]
    return tuple(ports)


def _work_ports():
    ports = []
    for k in range(1, WORK_OFFSETS + 1):
        p, g = f"work[{k}]", 53 + k
        ports += [
            real(f"{p}.x", "parameter", 0.0, "mm", f"work offset {k} (G{g}; G54 at power-on): X (radius, like the tool "
                 "offsets) of the axes at the part's programmed X 0, before the tool offset"),
            real(f"{p}.z", "parameter", 0.0, "mm", f"work offset {k} (G{g}): Z of the axes at the part's programmed "
                 "Z 0, before the tool offset"),
        ]
    return tuple(ports)


_PROGRAM_ONLY = {"x_diameter", "feed_per_rev", "x_home", "z_home", "spindle_band", "spindle_timeout", "thread_shift"}


@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)
class CutSequencer(CycleController):
    """Repetitive cut sequencer: four sub-cycles per pass, N passes per block, a series of blocks."""

    MODEL_NAME = "CutSequencer"
    DESCRIPTION = "Lathe repetitive-cut sequencer: SC1 infeed, SC2 cut (taper), SC3 retract, SC4 return (US 4,017,723)"
    SEED = "repetitive-cut-sequencer-US4017723.txt"
    STOP_TIME = 100.0
    AXES = ("x", "z")
    #: Rebuilt from the parameters, not saved with a state (fmi/state.py): what the program means.
    #: The status last written into ``out`` by :meth:`_publish` and that dict (a cache of what ``out`` holds).
    DERIVED: ClassVar[tuple[str, ...]] = (*CycleController.DERIVED, "meaning", "_status", "_status_of")

    PORTS = (
        real("x_start", "parameter", X_START, "mm", "X (radius) of the start point STP"),
        real("z_start", "parameter", Z_START, "mm", "Z of the start point STP"),
        integer("n_blocks", "parameter", 1, "number of blocks read in series", min=1, max=MAX_BLOCKS),
        real("accel", "parameter", 500.0, "mm/s2", "path acceleration/deceleration limit", min=0.0,
             min_exclusive=True),
        *cycle_ports("a sub-cycle"),
        *_block_ports(),
        boolean("start", "input", False, "cycle start (rising edge)"),
        boolean("feed_hold", "input", False, "feed hold: decelerate and stop on the path while true"),
        real("feed_override", "input", 1.0, "1", "feed override of the cutting feed (SC2)", min=0.0, max=1.5),
        boolean("alarm_in", "input", False, "external alarm (area limiter): latch alarm, decelerate to rest"),
        *servo_ports(("x", X_START), ("z", Z_START)),
        integer("subcycle", "output", None,
                "sub-cycle: 0 idle (or approach to STP), 1 infeed, 2 cut, 3 retract, 4 return"),
        integer("pass_no", "output", None, "pass of the current block, counting up from 1 (0 idle)"),
        integer("passes_left", "output", None, "the seed's pass down-counter (counts down at SC3 -> SC4)"),
        integer("block_no", "output", None, "block being run (0 idle)"),
        real("sigma_x", "output", None, "mm", "ΣX accumulator: Xf + n·Xd (a program's cycle: the pass's depth "
             "below the cycle's start point)"),
        boolean("busy", "output", None, "a cycle is running"),
        boolean("done", "output", None, "the last block has finished (until the next start)"),
        boolean("alarm", "output", None, "alarm latched (external alarm, bad input, excess following error)"),
        # last, so the value references of the ports before them stay what they were
        string("program", "parameter", "", "lathe part program in the Fanuc 0i-T dialect (README: O, N, X as a "
               "diameter (x_diameter), U/W, G00-G03 with I/K or R, G04, G28, G50 S, G96/G97, G98/G99, S, T, "
               "M00-M05, M08/M09, M30, G7/G8, G90/G91, G54-G59 (work[k]), M98/M99 subprograms, ,C ,R A) with G71 "
               "stock removal (G71 U R / G71 P Q U W F), G72 facing (G72 W R / G72 P Q U W F), G73 pattern repeat "
               "(G73 U W R / G73 P Q U W F), G70 finishing (G70 P Q F), G90/G94 single cycles, G74/G75 peck "
               "drilling and grooving, threads (G32, G92, G76 following the spindle), one block per line, "
               "starting at x_start/z_start; G00 and the cycles' rapid "
               "moves at block[1].rapid; empty: the registers block[k]"),
        integer("line", "output", None, "program line being executed, 1-based (0 idle, or no program)"),
        integer("canned_cycle", "output", None, "canned cycle running: 71 stock removal, 72 facing stock removal, "
                "73 pattern repeat, 70 finishing, 76 multiple threading, 92 thread cutting, 32 a G32 thread, "
                "90 turning, 94 facing (single cycles), 74 face peck drilling, 75 grooving, 0 none"),
        # the Fanuc 0i-T dialect of a program (appended: the value references before stay what they were)
        boolean("x_diameter", "parameter", True, "program: X and U are diameters until G7/G8, as on Fanuc's lathes; "
                "false: radii (the axes and every other length are radii)"),
        boolean("feed_per_rev", "parameter", False, "program: F is mm/rev (G99) until G98/G99; false: mm/min (G98), "
                "the power-on mode"),
        real("x_home", "parameter", 50.0, "mm", "X (radius, axes) of the machine reference G28 returns to"),
        real("z_home", "parameter", 50.0, "mm", "Z (axes) of the machine reference G28 returns to"),
        *_tool_ports(),
        real("spindle_band", "parameter", 0.05, "1", "speed arrival: a cut begins when the actual spindle speed is "
             "within this fraction of the commanded speed (Fanuc's SAR)", min=0.0, max=1.0, min_exclusive=True),
        real("spindle_timeout", "parameter", 10.0, "s", "alarm when the spindle has not arrived at speed this long "
             "after a cut was to begin", min=0.0, min_exclusive=True),
        real("spindle_speed", "input", 0.0, "rev/min", "actual spindle speed (from the spindle drive; its sign is "
             "the direction)"),
        boolean("optional_stop", "input", False, "optional-stop switch: M01 stops the program while true"),
        integer("tool", "output", None, "turret station of the active tool (T<tool><offset>; 0 none)"),
        real("s_cmd", "output", None, "rev/min", "commanded spindle speed (G97: S; G96: 1000 S / (pi D) at the "
             "tool's diameter, at most G50 S; 0 stopped)"),
        integer("spindle_dir", "output", None, "spindle direction: +1 M03, -1 M04, 0 M05"),
        boolean("coolant", "output", None, "coolant on (M08) / off (M09)"),
        # appended: the bar stock the part check cuts (read by the host's part check, not by the cycle), and
        # whether the present move runs at rapid
        real("stock_diameter", "parameter", STOCK_DIAMETER, "mm", "diameter of the bar stock (the part check's "
             "material; the cycle does not read it)", min=0.0, min_exclusive=True, max=2 * POSITION_LIMIT),
        real("stock_length", "parameter", STOCK_LENGTH, "mm", "length of the bar stock from its face toward the "
             "chuck (-Z)", min=0.0, min_exclusive=True, max=2 * POSITION_LIMIT),
        real("stock_face_z", "parameter", Z_START, "mm", "Z of the bar stock's face", min=-POSITION_LIMIT,
             max=POSITION_LIMIT),
        boolean("rapid", "output", None, "the present move runs at rapid (SC1, SC3, SC4 and the approach of the "
                "registers; G00 and the cycles' rapid moves of a program); false while cutting or idle"),
        # appended: the block-delete switch
        boolean("block_delete", "input", False, "block-delete switch: a program's blocks starting with / are "
                "skipped when it is on at START (the program is read, buffered, whole when it starts)"),
        # appended: threads (G32, G92, G76) follow the spindle's encoder
        real("revolutions", "input", 0.0, "rev", "actual spindle angle in revolutions, signed, continuous (the "
             "spindle drive's encoder): a thread starts at its one-revolution marker and Z follows it"),
        real("thread_shift", "parameter", 0.0, "deg", "a thread starts this far after the spindle's one-revolution "
             "marker (a multi-start thread: 360/starts apart)", min=0.0, max=360.0),
        boolean("threading", "output", None, "a thread pass follows the spindle (from its marker to its end)"),
        # appended: the tool table's shapes (the part check's)
        *_tool_shape_ports(),
        # appended: the work offsets G54..G59
        *_work_ports(),
    )

    # -- parameters -----------------------------------------------------------------------------
    @classmethod
    def unread(cls, values: Mapping[str, object]) -> dict[str, str]:
        out = super().unread(values)
        if str(values.get("program", "")).strip():
            for p in cls.ports("parameter"):
                if (p.name.startswith("block[") and p.name != "block[1].rapid") or p.name == "n_blocks":
                    out[p.name] = "runs its program (program is set), not the registers"
        else:
            for p in cls.ports("parameter"):
                if p.name.startswith(("tool[", "work[")) or p.name in _PROGRAM_ONLY:
                    out[p.name] = "runs the registers (program is empty): only a program reads it"
        return out

    def configure(self, values: Mapping[str, object]) -> None:
        self.x_start = real_param(values, "x_start")
        self.z_start = real_param(values, "z_start")
        self.n_blocks = int_param(values, "n_blocks")
        self.accel = real_param(values, "accel")
        self.configure_cycle(values)
        blocks = []
        for k in range(1, self.n_blocks + 1):
            p = f"block[{k}]"
            blocks.append(Block(
                Xf=real_param(values, f"{p}.Xf"),
                Xd=real_param(values, f"{p}.Xd"),
                Xp=real_param(values, f"{p}.Xp"),
                Zp=real_param(values, f"{p}.Zp"),
                N=int_param(values, f"{p}.N"),
                feed=real_param(values, f"{p}.feed"),
                rapid=real_param(values, f"{p}.rapid"),
                own_stp=bool(values[f"{p}.own_stp"]),
                x_stp=real_param(values, f"{p}.x_stp"),
                z_stp=real_param(values, f"{p}.z_stp"),
            ))
        self.blocks = blocks
        # the start point of every block: its own, else the previous block's
        stps, stp = [], (self.x_start, self.z_start)
        for b in blocks:
            stp = (b.x_stp, b.z_stp) if b.own_stp else stp
            stps.append(stp)
        self.stps = stps
        self.program = str(values["program"])
        for k in range(1, MAX_TOOLS + 1):
            # a row is one tool: a grooving blade, a drill, or else a turning insert
            p = f"tool[{k}]"
            width, drill = real_param(values, f"{p}.width"), real_param(values, f"{p}.drill_diameter")
            require(not (width > 0.0 and drill > 0.0), f"{p}.drill_diameter", drill,
                    f"must be 0 while {p}.width is {width:g}: a row of the tool table is one tool (a grooving "
                    "blade or a drill)")
            nose = real_param(values, f"{p}.nose_radius")
            require(not (width > 0.0 and nose > width / 2.0), f"{p}.nose_radius", nose,
                    f"must be <= half the grooving blade's width {p}.width {width:g}")
        self.spindle_band = real_param(values, "spindle_band")
        self.thread_shift = real_param(values, "thread_shift")
        self.spindle_timeout = real_param(values, "spindle_timeout")
        # the tool table: the one place its rows are read (the planner, the part check and the plots share them)
        tools = tuple(Tool(x_offset=real_param(values, f"tool[{k}].x_offset"),
                           z_offset=real_param(values, f"tool[{k}].z_offset"),
                           nose_radius=real_param(values, f"tool[{k}].nose_radius"),
                           tip=int_param(values, f"tool[{k}].tip"),
                           max_depth=real_param(values, f"tool[{k}].max_depth"),
                           insert_angle=real_param(values, f"tool[{k}].insert_angle"),
                           width=real_param(values, f"tool[{k}].width"),
                           drill_diameter=real_param(values, f"tool[{k}].drill_diameter"))
                      for k in range(1, MAX_TOOLS + 1))
        works = lathe_program.work_offsets(lambda name: real_param(values, name))
        home = (real_param(values, "z_home"), real_param(values, "x_home"))
        setup = lathe_program.Setup(diameter=bool(values["x_diameter"]), feed_per_rev=bool(values["feed_per_rev"]),
                                    tools=tools, home=home, works=works)
        stock = Stock(diameter=real_param(values, "stock_diameter"), length=real_param(values, "stock_length"),
                      face_z=real_param(values, "stock_face_z"))
        start = (self.x_start, self.z_start)
        # a part program replaces the registers: its moves start at x_start/z_start, G00 at block[1].rapid
        if self.program.strip():
            ops = lathe_program.parse(self.program, start, setup)
            self.plan: list[Segment] = lathe_program.plan_ops(ops, blocks[0].rapid, (self.z_start, self.x_start))
            self.meaning: ProgramMeaning = lathe_meaning(ops, lathe_program.read(self.program, lathe_program.LATHE),
                                                         start, tools, works, home, stock, setup.diameter)
        else:
            self.plan = []
            self.meaning = registers_meaning(self.stps, [(b.Xf + b.N * b.Xd, b.Xp, b.Zp) for b in blocks], start,
                                             tools, works, home, stock)
        # the plan with the block-delete switch on (the same plan when no block starts with '/'): chosen at START
        deleting = self.plan and lathe_program.has_block_delete(self.program)
        self.plans = (self.plan, lathe_program.plan(self.program, (self.x_start, self.z_start), blocks[0].rapid,
                                                    replace(setup, block_delete=True)) if deleting else self.plan)
        if self.plan:
            self.stps = [(self.x_start, self.z_start)]

    @classmethod
    def with_blocks(cls, blocks: list[Block] | tuple[Block, ...], **parameters: object) -> CutSequencer:
        """Build from :class:`Block` records instead of flat ``block[k].*`` names."""
        flat: dict[str, object] = {"n_blocks": len(blocks)}
        require(1 <= len(blocks) <= MAX_BLOCKS, "n_blocks", len(blocks), f"must be in 1..{MAX_BLOCKS}")
        for k, b in enumerate(blocks, start=1):
            for field in ("Xf", "Xd", "Xp", "Zp", "N", "feed", "rapid", "own_stp", "x_stp", "z_stp"):
                flat[f"block[{k}].{field}"] = getattr(b, field)
        flat.update(parameters)
        return cls(**flat)

    # -- state ----------------------------------------------------------------------------------
    def reset(self) -> None:
        self.phase = IDLE
        self.block_index = 0          # 0-based index into self.blocks while busy
        self.sigma_x = 0.0            # ΣX register
        self.passes_left = 0          # reversible pass counter
        self.pass_no = 0
        self.busy = False
        self.done = False
        self.reset_cycle()
        self.x_cmd, self.z_cmd = self.x_start, self.z_start
        self.x_vff = self.z_vff = 0.0
        self.move = ElementMove(self.accel) if self.plan else LinearMove(self.accel)
        self.segment = 0                     # index into self.plan while a program runs
        self._waypoints: list[tuple[float, float]] = []
        self._then_block = 0                 # block to begin once the approach is done
        self.dwell_left = 0.0                # s of a G04 dwell still to wait
        self.stop_wait = False               # at an M00 (or M01 with optional_stop): waiting for START
        self.spindle_wait: float | None = None   # s waited for the spindle to arrive at speed (None: not waiting)
        self.program_started = False         # a program's state (tool, spindle ...) is its present move's
        self._outputs: dict[str, object] = {}
        self._status: tuple[object, ...] = ()
        self._status_of: dict[str, object] | None = None
        self.rapid = False                   # the present move runs at rapid (kept through a controlled stop)
        self._optional_stop = False
        self._block_delete = False
        self._pressed = False
        self.threading = False               # a thread pass follows the spindle
        self.thread_armed = False            # a thread waits for its marker: thread_last is the angle seen before
        self.thread_last = 0.0               # turns (from the marker + thread_shift) of the last step, waiting
        self.thread_rev0 = 0.0               # turns at which the present thread segment started
        self.thread_travel = 0.0             # mm of Z the present thread segment has commanded
        self.thread_speed = 0.0              # mm/s along the path the thread commanded in its last step
        self._publish()

    # -- the cycle ------------------------------------------------------------------------------
    def _begin_phase(self, phase: int) -> None:
        """Load the distance counters for ``phase`` (the seed's non-destructive transfers)."""
        b = self.blocks[self.block_index]
        self.inpos.reset()
        here = (self.x_cmd, self.z_cmd)
        stp = x0, z0 = self.stps[self.block_index]
        self.phase = phase
        if phase == SC1:
            self.sigma_x += b.Xd                   # ΣX <- ΣX + Xd at the start of every pass
            self.pass_no += 1
            self.move.begin(here, (x0 - self.sigma_x, z0), b.rapid)
        elif phase == SC2:
            self.move.begin(here, (x0 - self.sigma_x - b.Xp, z0 - b.Zp), b.feed)
        elif phase == SC3:
            self.move.begin(here, (x0 - b.Xp, z0 - b.Zp), b.rapid)
        elif phase == SC4:
            self.passes_left -= 1                  # the SC3/4 shift pulse counts the pass down
            self.move.begin(here, stp, b.rapid)
        elif phase == APPROACH:
            self.move.begin(here, self._waypoints.pop(0), self.blocks[self._then_block].rapid)

    def _begin_segment(self, index: int) -> None:
        """Run the program's move ``index``: its sub-cycle, pass and ΣX are what the plan says."""
        seg = self.plan[index]
        self.inpos.reset()
        self.segment = index
        self.phase = seg.subcycle if seg.subcycle else PROGRAM_MOVE
        self.pass_no, self.sigma_x = seg.pass_no, seg.sigma_x
        self.program_started = True
        self.dwell_left = seg.dwell
        self.stop_wait = seg.stop == 1 or (seg.stop == 2 and self._optional_stop)
        turning = seg.modal.spindle and seg.modal.rpm(self.x_cmd - seg.modal.offset[1]) > 0
        self.spindle_wait = 0.0 if seg.feed and turning and not seg.continues else None
        self.threading = self.thread_armed = False
        self.thread_travel = self.thread_speed = 0.0
        assert isinstance(self.move, ElementMove)
        self.move.begin_element(seg.element, seg.rate)

    def _begin_block(self, index: int) -> None:
        if self.plan:
            self._begin_segment(0)
            return
        self.block_index = index
        b = self.blocks[index]
        self.sigma_x = b.Xf                         # Xf is loaded once per block
        self.passes_left = b.N
        self.pass_no = 0
        self._begin_phase(SC1)

    def _approach(self, index: int) -> None:
        """Go to block ``index``'s start point safely (X clear first, then Z, then X), then begin it."""
        (x0, z0), (x1, z1) = (self.x_cmd, self.z_cmd), self.stps[index]
        # +X is away from the work; the highest start point of any block is above every surface they cut
        clear = max(x0, x1, max(x for x, _ in self.stps))
        path = [(clear, z0), (clear, z1), (x1, z1)]
        points, here = [], (x0, z0)
        for p in path:
            if abs(p[0] - here[0]) > 1e-9 or abs(p[1] - here[1]) > 1e-9:
                points.append(p)
                here = p
        if not points:
            self._begin_block(index)
            return
        self._waypoints, self._then_block = points, index
        self.block_index = index
        self.sigma_x, self.passes_left, self.pass_no = 0.0, 0, 0
        self._begin_phase(APPROACH)

    def _start_cycle(self) -> None:
        self.busy, self.done = True, False
        if self.plan:
            # Fanuc reads the switch as it buffers a block; this controller buffers the whole program at START
            self.plan = self.plans[self._block_delete]
        self._approach(0)

    def _next_phase(self) -> None:
        if self.plan and self.phase != APPROACH:
            if self.segment + 1 < len(self.plan):
                self._begin_segment(self.segment + 1)
            else:
                self.phase = IDLE
                self.busy, self.done = False, True
                self.pass_no, self.sigma_x = 0, 0.0
            return
        if self.phase == APPROACH:
            if self._waypoints:
                self._begin_phase(APPROACH)
            else:
                self._begin_block(self._then_block)
        elif self.phase in (SC1, SC2, SC3):
            self._begin_phase(self.phase + 1)
        elif self.passes_left > 0:
            self._begin_phase(SC1)
        elif self.block_index + 1 < self.n_blocks:
            self._approach(self.block_index + 1)      # read the next block (from its start point)
        else:
            self.phase = IDLE
            self.busy, self.done = False, True
            self.pass_no = 0

    # -- the hooks of the NC cycle (controllers/cycle.py owns the order of a step) -----------------
    def halt(self) -> None:
        """The present move comes to a controlled stop along its path; the cycle ends. A thread stops from the
        speed the spindle gave it (its Z no longer follows the spindle: the thread is spoilt, as on a machine)."""
        if self.threading:
            self.move.v = self.thread_speed
        self.threading = self.thread_armed = False
        self.move.halt()
        self.phase = IDLE
        self.busy = False
        self._waypoints = []

    def watching_following_error(self) -> bool:
        return True                                  # always, at rest too: why in CycleController

    def command_point(self) -> list[float]:
        return [self.x_cmd, self.z_cmd]

    def read_buttons(self, inputs: Mapping[str, object]) -> Any:
        """START's edge, kept for a program's stop (M00/M01) too, and the optional-stop switch. The inputs
        appended later are read with their defaults: a caller that gives the first release's inputs runs as
        before (no optional stop, a spindle standing still)."""
        self._pressed = bool(super().read_buttons(inputs))
        self._optional_stop = bool(input_or(inputs, "optional_stop", False))
        self._block_delete = bool(input_or(inputs, "block_delete", False))
        return self._pressed

    def rebase(self, actual: Mapping[str, float]) -> None:
        self.x_cmd, self.z_cmd = actual["x"], actual["z"]
        self.move.begin((self.x_cmd, self.z_cmd), (self.x_cmd, self.z_cmd), 1.0)

    def begin(self, t: float, edges: Any) -> None:
        self._start_cycle()

    def advance(self, t: float, dt: float, inputs: Mapping[str, object], why: str | None) -> None:
        if self.busy:
            override = self.override.read(self, t, as_float(inputs["feed_override"]))
            cutting = self.plan[self.segment].feed if self.plan and self.phase != APPROACH else self.phase == SC2
            scale = 0.0 if inputs["feed_hold"] else (override if cutting else 1.0)
            self.rapid = not cutting
            held = False
            if self.plan and self.phase != APPROACH:
                scale, held = self._machine(t, dt, inputs, scale)
            if not held:
                self.move.advance(dt, scale)
                if self.arrival(t, dt, self.move.done, inputs):
                    self._next_phase()
            self.x_cmd, self.z_cmd = self.move.position()
            self.x_vff, self.z_vff = self.move.velocity()
        elif not self.move.done:
            self.move.advance(dt, 0.0)                 # the controlled stop after an alarm
            self.x_cmd, self.z_cmd = self.move.position()
            self.x_vff, self.z_vff = self.move.velocity()
        else:
            self.x_vff = self.z_vff = 0.0

    def _machine(self, t: float, dt: float, inputs: Mapping[str, object], scale: float) -> tuple[float, bool]:
        """A program's move waits for its dwell, for START at a stop and, at a cut's start, for the spindle to
        arrive at speed (held: the move neither starts nor ends); a feed per revolution follows the actual
        spindle speed. Returns the feed scale and whether the move is held."""
        seg = self.plan[self.segment]
        if seg.lead:
            return self._thread(t, dt, inputs, seg)
        if self.dwell_left > DWELL_EPS:
            self.dwell_left = max(self.dwell_left - dt, 0.0)
            return 0.0, True
        if self.stop_wait:
            self.stop_wait = not self._pressed
            return 0.0, True
        actual = abs(as_float(input_or(inputs, "spindle_speed", 0.0)))
        if self.spindle_wait is not None and not self._speed_arrived(t, dt, actual, seg):
            return 0.0, True
        if seg.feed and seg.modal.per_rev:
            self.move.rate = ElementMove.rate_on(seg.element, seg.rate * actual, self.accel)
        return scale, False

    def _speed_arrived(self, t: float, dt: float, actual: float, seg: Segment) -> bool:
        """A cut waits for the spindle to arrive at speed (Fanuc's SAR); an alarm ``spindle_timeout`` later."""
        wanted = seg.modal.rpm(self.x_cmd - seg.modal.offset[1])
        if abs(actual - wanted) <= self.spindle_band * wanted:
            self.spindle_wait = None
            return True
        wait = (self.spindle_wait or 0.0) + dt
        self.spindle_wait = wait
        if wait > self.spindle_timeout:
            self.stop(t, f"spindle: {actual:.1f} rev/min, not within {self.spindle_band:g} of the commanded "
                         f"{wanted:.1f} rev/min {self.spindle_timeout:g} s after the cut on line {seg.line} "
                         "was to begin (speed arrival)")
        return False

    def _thread(self, t: float, dt: float, inputs: Mapping[str, object], seg: Segment) -> tuple[float, bool]:
        """A thread segment: after the speed arrival it waits for the spindle's one-revolution marker (+
        ``thread_shift``), then commands Z from the **actual** spindle angle, z = z0 - lead * (turns - turns0),
        X following Z along the segment; no velocity feed-forward (the servo's lag is the machine's). Feed
        override does not apply; feed hold holds the start and acts at the thread block's end (as on a Fanuc).
        Always held for :meth:`advance`: this moves the command itself."""
        move = self.move
        if move.done:                          # the command reached the thread's end: the in-position check
            self.threading = self.thread_armed = False
            if self.arrival(t, dt, True, inputs):
                self._next_phase()
            return 0.0, True
        rev = as_float(input_or(inputs, "revolutions", 0.0))
        if not abs(rev) <= POSITION_LIMIT:        # false for NaN too
            self.stop(t, f"revolutions = {rev!r}: the spindle's encoder angle must be finite, within "
                         f"{POSITION_LIMIT:g} rev (the thread on line {seg.line})")
            return 0.0, True
        turns = rev * seg.modal.spindle - self.thread_shift / 360.0
        if not self.threading:
            if self.spindle_wait is not None:
                actual = abs(as_float(input_or(inputs, "spindle_speed", 0.0)))
                if not self._speed_arrived(t, dt, actual, seg):
                    return 0.0, True
            if not self.thread_armed or inputs["feed_hold"] or math.floor(turns) <= math.floor(self.thread_last):
                self.thread_armed = not inputs["feed_hold"]
                self.thread_last = turns
                return 0.0, True
            self.thread_rev0 = float(math.floor(turns))        # the marker passed within this step
            self.thread_travel = 0.0
            self.threading = True
        z0, z1 = seg.element.start[0], seg.element.end[0]
        length_z = abs(z1 - z0)
        travel = seg.lead * (turns - self.thread_rev0)
        step = travel - self.thread_travel
        if step < -THREAD_BACKLASH or step > SPEED_LIMIT * dt:
            self.stop(t, f"revolutions = {rev!r}: the spindle's angle moved {step / seg.lead:+.4g} rev in one step "
                         f"during the thread on line {seg.line} (backwards, or faster than any axis follows)")
            return 0.0, True
        if travel >= length_z:
            nxt = self.segment + 1
            if nxt < len(self.plan) and self.plan[nxt].continues:
                rev0 = self.thread_rev0 + length_z / seg.lead
                self._begin_segment(nxt)
                self.threading, self.thread_rev0 = True, rev0
                return self._thread(t, dt, inputs, self.plan[nxt])
            self.thread_speed = 0.0
            move.s, move.v, move.done = move.length, 0.0, True
            self.threading = self.thread_armed = False
            if self.arrival(t, dt, True, inputs):
                self._next_phase()
            return 0.0, True
        self.thread_speed = max(step, 0.0) / dt * move.length / length_z
        self.thread_travel = travel
        move.s = travel * move.length / length_z
        return 0.0, True

    def _per_rev_now(self) -> bool:
        """The present move is a program's feed per revolution (G99): its rate follows the spindle."""
        if not (type(self.segment) is int and 0 <= self.segment < len(self.plan)):
            return False
        seg = self.plan[self.segment]
        return seg.feed and seg.modal.per_rev and self.phase != APPROACH

    def _publish(self) -> dict[str, object]:
        out = self._outputs
        out["x_cmd"], out["z_cmd"] = self.x_cmd, self.z_cmd
        out["x_vff"], out["z_vff"] = self.x_vff, self.z_vff
        running = self.busy and bool(self.plan) and self.phase != APPROACH
        program = bool(self.plan) and self.program_started
        seg = self.plan[self.segment] if running or program else None
        status: tuple[object, ...] = (
            self.phase if self.phase > 0 else 0, self.pass_no, self.passes_left,
            self.block_index + 1 if self.busy else 0, self.sigma_x,
            seg.line if running and seg is not None else 0, seg.cycle if running and seg is not None else 0,
            self.busy, self.done, self.alarm, self.rapid and (self.busy or not self.move.done), self.threading,
            program)
        # The status changes at a phase, pass or block, rarely within one: written into ``out`` only when it did (one
        # tuple compared instead of twelve dictionary stores a step), and always into another ``out`` (a reset's, a
        # restored state's: the cache describes the dict it was written into).
        if self._status_of is not out or status != self._status:
            (out["subcycle"], out["pass_no"], out["passes_left"], out["block_no"], out["sigma_x"], out["line"],
             out["canned_cycle"], out["busy"], out["done"], out["alarm"], out["rapid"], out["threading"], _) = status
            if not program:                               # the registers, or before the program's first move
                out["tool"], out["spindle_dir"], out["coolant"], out["s_cmd"] = _NO_PROGRAM_MODAL
            self._status, self._status_of = status, out
        if not program or seg is None:
            return out
        modal = seg.modal
        out["tool"], out["spindle_dir"], out["coolant"] = modal.tool, modal.spindle, modal.coolant
        if modal.css:                                     # G96: at the tool's X (a rapid: at its end, as Fanuc)
            x = self.x_cmd if seg.feed else seg.element.end[1]
            out["s_cmd"] = modal.rpm(x - modal.offset[1])
        else:
            out["s_cmd"] = modal.rpm(0.0)
        return out

    def check_state(self, inputs: Mapping[str, object]) -> str | None:
        """A restored state: the registers within the present block, the command where the interpolator
        stands and (while running) within max_following_error (and one step) of the actual axes."""
        from .base import POSITION_LIMIT  # here: this check is one self-contained piece
        why = super().check_state(inputs)
        if why:
            return why
        rates = {0.0, 1.0} | {b.rapid for b in self.blocks} | {b.feed for b in self.blocks}
        rates |= {ElementMove.rate_on(g.element, g.rate, self.accel) for g in self.plan}
        why = self._program_fault() if self.plan else None
        if why:
            return why
        if self.plan and self._per_rev_now():
            rates.add(self.move.rate)            # a feed per revolution: the rate follows the spindle (checked there)
        if not isinstance(self.move, ElementMove) or self.move.arc is None:
            why = self.move_fault(self.move, self.accel, rates)
            if why:
                return why
        if self.phase not in (APPROACH, IDLE, SC1, SC2, SC3, SC4) + ((PROGRAM_MOVE,) if self.plan else ()):
            return f"phase = {self.phase!r}: not a sub-cycle"
        for name in ("block_index", "_then_block"):
            if not 0 <= getattr(self, name) < self.n_blocks:
                return f"{name} = {getattr(self, name)!r}: not a block of n_blocks = {self.n_blocks}"
        b = self.blocks[self.block_index]
        if self.plan:
            pass                                  # a program's pass and ΣX: checked by _program_fault
        elif not (0 <= self.passes_left <= b.N and 0 <= self.pass_no <= b.N):
            return f"passes_left = {self.passes_left!r}, pass_no = {self.pass_no!r}: not within N = {b.N}"
        elif not 0.0 <= self.sigma_x <= b.Xf + b.N * b.Xd + 1e-9:
            return f"sigma_x = {self.sigma_x!r}: not within 0..Xf + N*Xd = {b.Xf + b.N * b.Xd:g}"
        for i, p in enumerate(self._waypoints):
            if type(p) is not tuple or len(p) != 2 or not all(type(x) is float and abs(x) <= POSITION_LIMIT for x in p):
                return f"_waypoints[{i}] = {p!r}: not an (x, z) position within {POSITION_LIMIT:g} mm"
        here = (self.x_cmd, self.z_cmd)
        if here != self.move.position() and not (self.move.end_point == () and here == (self.x_start, self.z_start)):
            return f"x_cmd, z_cmd = {here!r}: not where the interpolator stands ({self.move.position()!r})"
        if (self.x_vff, self.z_vff) not in (self.move.velocity(), (0.0, 0.0)):
            return f"x_vff, z_vff = {(self.x_vff, self.z_vff)!r}: not the interpolator's velocity"
        if self.busy and not self.alarm:
            why = self.reach_fault(inputs, {"x": self.x_cmd, "z": self.z_cmd})
            if why:
                return why
        return self.outputs_fault()

    def _program_fault(self) -> str | None:
        """A restored state of a running program: the move is the plan's present segment (an arc with the arc's
        own acceleration, rate cap and length), the pass and ΣX are the segment's."""
        if not (isinstance(self.move, ElementMove) and type(self.segment) is int
                and 0 <= self.segment < len(self.plan)):
            return f"segment = {self.segment!r}: not a move of the program ({len(self.plan)} moves)"
        seg = self.plan[self.segment]
        if not (type(self.dwell_left) is float and 0.0 <= self.dwell_left <= seg.dwell):
            return f"dwell_left = {self.dwell_left!r}: not within the move's dwell 0..{seg.dwell:g} s"
        for flag in ("stop_wait", "program_started", "_pressed", "_optional_stop", "_block_delete", "threading",
                     "thread_armed"):
            if type(getattr(self, flag)) is not bool:
                return f"{flag} = {getattr(self, flag)!r}: not a bool"
        for name in ("thread_last", "thread_rev0", "thread_travel", "thread_speed"):
            if not (type(getattr(self, name)) is float and abs(getattr(self, name)) <= POSITION_LIMIT):
                return f"{name} = {getattr(self, name)!r}: not a finite float"
        if (self.threading or self.thread_armed) and not (seg.lead and self.busy):
            return f"threading = {self.threading!r}: the program's move {self.segment} is no thread"
        if self.stop_wait and not seg.stop:
            return f"stop_wait = True: the program's move {self.segment} is no stop (M00/M01)"
        if self.spindle_wait is not None and not (type(self.spindle_wait) is float
                                                  and 0.0 <= self.spindle_wait <= self.spindle_timeout + 1.0):
            return f"spindle_wait = {self.spindle_wait!r}: not None or 0..spindle_timeout s"
        if self._per_rev_now():
            top = ElementMove.rate_on(seg.element, seg.rate * 1e5, self.accel)
            if not (type(self.move.rate) is float and 0.0 <= self.move.rate <= top):
                return f"move.rate = {self.move.rate!r}: not a feed per revolution of this move (0..{top:g})"
        running = self.busy and self.phase != APPROACH
        if running and (self.pass_no, self.sigma_x) != (seg.pass_no, seg.sigma_x):
            return f"pass_no, sigma_x = {(self.pass_no, self.sigma_x)!r}: not the program's move {self.segment}"
        m = self.move
        if m.arc is not None:
            if m.arc != seg.element:
                return f"move.arc = {m.arc!r}: not the program's move {self.segment}"
            cap = m.rate if self._per_rev_now() else ElementMove.rate_on(m.arc, seg.rate, self.accel)
            if (m.accel, m.rate, m.length) != (ARC_TANGENTIAL * self.accel, cap, m.arc.length):
                return f"move.accel, rate, length = {(m.accel, m.rate, m.length)!r}: not those of its arc"
            if not (0.0 <= m.s <= m.length and 0.0 <= m.v <= 1.5 * m.rate):
                return f"move.s = {m.s!r}, v = {m.v!r}: not within the arc (length {m.length!r})"
        return None
