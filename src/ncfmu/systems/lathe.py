"""The lathe systems: operator panel -> cut sequencer -> area limiter -> X and Z servos; the sequencer's spindle
commands (a program's S, M03/M04/M05, G96) drive the spindle, whose actual speed the sequencer reads back (the
speed-arrival wait, feed per revolution) and whose encoder angle a thread's Z follows (spindle.revolutions)."""

from __future__ import annotations

from ..cosim.ssp import System
from .compose import REPEATS, blocks, component, table, wire
from .part import LathePart
from .report import Axes, Envelope, LatheCycle, Plane, Report

#: Lathe envelope: reference Z, limited X. For Z <= -45 (the chuck) X must be >= 40: out of reach.
CHUCK_TABLE = [(-45.0, 40.0, 1e6), (1e6, -1e6, 1e6)]
#: The start point STP: X (radius) 30, Z 2; the stock radius is 29.
X_START, Z_START = 30.0, 2.0
#: The bar stock: 58 mm in diameter, its face at Z 0, 80 mm long (from Z -45 on it is held in the chuck).
STOCK = dict(stock_diameter=58.0, stock_length=80.0, stock_face_z=0.0)

REPORT = Report(
    (LatheCycle(seq="seq", x="x_axis", z="z_axis"),
     Envelope(limiter="limiter", ref="z_axis", lim="x_axis", region_names=("chuck",)),
     Axes(("x_axis", "z_axis")),
     LathePart(seq="seq", x="x_axis", z="z_axis", limiter="limiter", spindle="spindle")),
    Plane(horizontal="z_axis", vertical="x_axis", title="tool path in the X-Z plane", xlabel="Z [mm]",
          ylabel="X (radius) [mm]"),
    repeats=REPEATS)


def _lathe(name: str, description: str, stop_time: float, program: dict[str, object]) -> System:
    return System(
        name=name,
        description=description,
        components=[
            component("panel", "OperatorPanel", start_at=0.1),
            component("seq", "CutSequencer", x_start=X_START, z_start=Z_START, **STOCK, **program),
            component("limiter", "AreaLimiter", ref_start=Z_START, lim_start=X_START, predictive=True,
                      use_actual=True, **table(CHUCK_TABLE)),
            component("x_axis", "ServoAxis", pos_start=X_START),
            component("z_axis", "ServoAxis", pos_start=Z_START),
            component("spindle", "SpindleDrive"),
        ],
        connections=wire(
            "panel.start -> seq.start", "panel.feed_hold -> seq.feed_hold",
            "panel.feed_override -> seq.feed_override",
            "seq.z_cmd -> limiter.ref_cmd_in", "seq.z_vff -> limiter.ref_vff_in",
            "seq.x_cmd -> limiter.lim_cmd_in", "seq.x_vff -> limiter.lim_vff_in",
            "limiter.lim_cmd -> x_axis.pos_cmd", "limiter.lim_vff -> x_axis.vel_ff",
            "limiter.ref_cmd -> z_axis.pos_cmd", "limiter.ref_vff -> z_axis.vel_ff",
            "limiter.alarm -> seq.alarm_in",
            "x_axis.pos -> seq.x_pos", "x_axis.in_position -> seq.x_in_position",
            "z_axis.pos -> seq.z_pos", "z_axis.in_position -> seq.z_in_position",
            "x_axis.pos -> limiter.lim_pos", "z_axis.pos -> limiter.ref_pos",
            "seq.s_cmd -> spindle.speed_cmd", "seq.spindle_dir -> spindle.direction",
            "spindle.speed -> seq.spindle_speed", "spindle.revolutions -> seq.revolutions",
        ),
        stop_time=stop_time,
    )


def lathe_roughing() -> System:
    """Rough series (Xf 1.0, Xd 0.5, N 6) then finish series (Xf 4.0, Xd 0.1, N 1): final radius 25.9 mm."""
    return _lathe("lathe_roughing",
                  "Lathe: sequencer -> area limiter -> X and Z servos; 6 roughing passes, 1 finishing pass",
                  95.0, blocks(dict(Xf=1.0, Xd=0.5, Xp=0.0, Zp=42.0, N=6, feed=4.0, rapid=50.0),
                               dict(Xf=4.0, Xd=0.1, Xp=0.0, Zp=42.0, N=1, feed=2.0, rapid=50.0)))


def lathe_taper() -> System:
    """One taper block: Xf 1.0, Xd 0.5, N 4, Zp 42, Xp 1.5."""
    return _lathe("lathe_taper", "Lathe: taper cut, 4 passes, X falls 1.5 mm over the 42 mm cut",
                  50.0, blocks(dict(Xf=1.0, Xd=0.5, Xp=1.5, Zp=42.0, N=4, feed=4.0, rapid=50.0)))
