"""The grinder systems: programmable feed on the wheel head, alone or inside a limit envelope."""

from __future__ import annotations

from ..cosim.ssp import System
from .compose import REPEATS, component, table, wire
from .part import GrindPart
from .report import Axes, Envelope, FeedCycle, Plane, Report

#: The seed's Table 1 (programmable-feed-JPS6043522.txt): rapid approach, rough, fine, spark-out, return;
#: EMB and wear cycles.
SEED_PROGRAM = ("M0: X+D3F7; M1: X+D2F1; M2: X+D5F2; M3: T1; M4: X-D4F7; M5: END; "
                "M41: XF7S1; M42: END; M43: X+D1F2S4; M44: END")

#: Grinder envelope: reference Y (table), limited X (infeed).
GRINDER_TABLE = [(200.0, -100.0, 250.0),    # dresser
                 (350.0, -100.0, 80.0),     # headstock
                 (800.0, -100.0, 180.0),    # work
                 (1000.0, -100.0, 60.0)]    # tailstock

#: Traverse to the work, approach, grind, spark out, retract, traverse back. EMB retracts X first.
ENVELOPE_PROGRAM = ("M0: Y+D1F7; M1: X+D2F7; M2: X+D3F1; M3: T1; M4: X-D4F7; M5: Y-D1F7; M6: END; "
                    "M41: XF7S1; M42: YF7S1; M43: END; M45: X+D5F2S4; M46: END")

FEED_REPORT = Report((FeedCycle(feed="feed", x="x_axis", hold="panel.feed_hold"), Axes(("x_axis",)),
                      GrindPart(feed="feed", x="x_axis")), repeats=REPEATS)
ENVELOPE_REPORT = Report(
    (FeedCycle(feed="feed", x="x_axis", hold="panel.feed_hold"),
     Envelope(limiter="limiter", ref="y_axis", lim="x_axis", region_names=("dresser", "headstock", "work",
                                                                            "tailstock")),
     Axes(("x_axis", "y_axis")),
     GrindPart(feed="feed", x="x_axis")),
    Plane(horizontal="y_axis", vertical="x_axis", title="wheel path in the Y-X plane with the limit envelope",
          xlabel="Y (table) [mm]", ylabel="X (infeed) [mm]", path_label="wheel (actual)"),
    repeats=REPEATS)

_PANEL_TO_FEED = ("panel.start -> feed.start", "panel.wear_start -> feed.wear_start",
                  "panel.emergency -> feed.emergency", "panel.feed_hold -> feed.feed_hold",
                  "panel.feed_override -> feed.feed_override", "panel.mfin -> feed.mfin",
                  "feed.m_active -> panel.m_active")


def grinder_feed() -> System:
    """The seed's program on the wheel head: rapid 4.0, rough to 4.2, fine to 4.3, spark-out 1.5 s, return."""
    return System(
        name="grinder_feed",
        description="Grinder: operator panel -> programmable feed -> X (wheel-head infeed) servo",
        components=[
            component("panel", "OperatorPanel", start_at=0.1),
            component("feed", "ProgrammableFeed", program=SEED_PROGRAM, D1=0.02, D2=0.20, D3=4.0, D4=4.30,
                      D5=0.10, F1=0.02, F2=0.005, F7=10.0, T1=1.5, x_origin=0.0),
            component("x_axis", "ServoAxis", pos_start=0.0),
        ],
        connections=wire(*_PANEL_TO_FEED,
                         "feed.x_cmd -> x_axis.pos_cmd", "feed.x_vff -> x_axis.vel_ff",
                         "x_axis.pos -> feed.x_pos", "x_axis.in_position -> feed.x_in_position"),
        stop_time=35.0,
    )


def grinder_envelope() -> System:
    """Programmable feed on X and Y -> area limiter (dresser, headstock, work, tailstock) -> X and Y servos."""
    x0, y0 = 0.0, 100.0
    return System(
        name="grinder_envelope",
        description="Grinder: programmable feed on X and Y -> area limiter -> X and Y servos",
        components=[
            component("panel", "OperatorPanel", start_at=0.1),
            component("feed", "ProgrammableFeed", program=ENVELOPE_PROGRAM, wear_address=45,
                      D1=400.0, D2=150.0, D3=20.0, D4=170.0, D5=0.05, F1=2.0, F2=0.005, F7=100.0, T1=1.0,
                      x_origin=x0, y_origin=y0),
            component("limiter", "AreaLimiter", ref_start=y0, lim_start=x0, predictive=True, use_actual=True,
                      **table(GRINDER_TABLE)),
            component("x_axis", "ServoAxis", pos_start=x0),
            component("y_axis", "ServoAxis", pos_start=y0),
        ],
        connections=wire(*_PANEL_TO_FEED,
                         "feed.y_cmd -> limiter.ref_cmd_in", "feed.y_vff -> limiter.ref_vff_in",
                         "feed.x_cmd -> limiter.lim_cmd_in", "feed.x_vff -> limiter.lim_vff_in",
                         "limiter.lim_cmd -> x_axis.pos_cmd", "limiter.lim_vff -> x_axis.vel_ff",
                         "limiter.ref_cmd -> y_axis.pos_cmd", "limiter.ref_vff -> y_axis.vel_ff",
                         "limiter.alarm -> feed.alarm_in",
                         "x_axis.pos -> feed.x_pos", "x_axis.in_position -> feed.x_in_position",
                         "y_axis.pos -> feed.y_pos", "y_axis.in_position -> feed.y_in_position",
                         "x_axis.pos -> limiter.lim_pos", "y_axis.pos -> limiter.ref_pos"),
        stop_time=25.0,
    )
