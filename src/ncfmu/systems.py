"""The systems of SPEC section 5, defined once here and written to ``ssp/<system>/`` as SSP 1.0.

Components are listed in Gauss-Seidel order (operator panel, controller, servos); the master steps
them in that order. Connector types and units come from the controllers' port tables.
"""

from __future__ import annotations

from collections.abc import Callable

from .controllers import AreaLimiter, ContourInterpolator, CutSequencer, OperatorPanel, ProgrammableFeed
from .controllers.base import Controller
from .cosim.ssp import Component, Connection, System
from .errors import SystemDefinitionError
from .ports import to_float, to_int
from .servo.axis import ServoAxis

MODELS: dict[str, type[Controller]] = {c.MODEL_NAME: c for c in (CutSequencer, OperatorPanel, ServoAxis, AreaLimiter,
                                                                  ProgrammableFeed, ContourInterpolator)}


def _component(name: str, model: str, **parameters: object) -> Component:
    logic = MODELS[model]
    known = {p.name: p for p in logic.ports("parameter")}
    for key in parameters:
        if key not in known:
            raise SystemDefinitionError(f"{model} has no parameter {key!r}")
    connectors: list[tuple[str, str, str, str | None]] = [
        (p.name, p.causality, p.type, p.unit) for p in logic.PORTS if p.causality in ("input", "output")]
    typed = {k: (to_int(v) if known[k].type == "Integer" else bool(v) if known[k].type == "Boolean"
                 else to_float(v) if known[k].type == "Real" else v) for k, v in parameters.items()}
    return Component(name, model, typed, connectors)


def _wire(*pairs: str) -> list[Connection]:
    out = []
    for pair in pairs:
        src, dst = (s.strip() for s in pair.split("->"))
        (a, b), (c, d) = src.split(".", 1), dst.split(".", 1)
        out.append(Connection(a, b, c, d))
    return out


def _blocks(*blocks: dict) -> dict[str, object]:
    flat: dict[str, object] = {"n_blocks": len(blocks)}
    for k, b in enumerate(blocks, start=1):
        for key, value in b.items():
            flat[f"block[{k}].{key}"] = value
    return flat


def _table(rows: list[tuple[float, float, float]]) -> dict[str, object]:
    flat: dict[str, object] = {"n_regions": len(rows)}
    for i, (ref_max, lo, hi) in enumerate(rows, start=1):
        flat[f"region[{i}].ref_max"], flat[f"region[{i}].lim_min"], flat[f"region[{i}].lim_max"] = ref_max, lo, hi
    return flat


#: Lathe envelope: reference Z, limited X. For Z <= -45 (the chuck) X must be >= 40: out of reach.
CHUCK_TABLE = [(-45.0, 40.0, 1e6), (1e6, -1e6, 1e6)]


def _lathe(name: str, description: str, stop_time: float, blocks: dict[str, object]) -> System:
    x0, z0 = 30.0, 2.0
    return System(
        name=name,
        description=description,
        components=[
            _component("panel", "OperatorPanel", start_at=0.1),
            _component("seq", "CutSequencer", x_start=x0, z_start=z0, **blocks),
            _component("limiter", "AreaLimiter", ref_start=z0, lim_start=x0, predictive=True, use_actual=True,
                       **_table(CHUCK_TABLE)),
            _component("x_axis", "ServoAxis", pos_start=x0),
            _component("z_axis", "ServoAxis", pos_start=z0),
        ],
        connections=_wire(
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
        ),
        stop_time=stop_time,
    )


def lathe_roughing() -> System:
    """Rough series (Xf 1.0, Xd 0.5, N 6) then finish series (Xf 4.0, Xd 0.1, N 1): final radius 25.9 mm."""
    return _lathe("lathe_roughing",
                  "Lathe: sequencer -> area limiter -> X and Z servos; 6 roughing passes, 1 finishing pass",
                  95.0, _blocks(dict(Xf=1.0, Xd=0.5, Xp=0.0, Zp=42.0, N=6, feed=4.0, rapid=50.0),
                                dict(Xf=4.0, Xd=0.1, Xp=0.0, Zp=42.0, N=1, feed=2.0, rapid=50.0)))


def lathe_taper() -> System:
    """One taper block: Xf 1.0, Xd 0.5, N 4, Zp 42, Xp 1.5."""
    return _lathe("lathe_taper", "Lathe: taper cut, 4 passes, X falls 1.5 mm over the 42 mm cut",
                  50.0, _blocks(dict(Xf=1.0, Xd=0.5, Xp=1.5, Zp=42.0, N=4, feed=4.0, rapid=50.0)))


_PANEL_TO_FEED = ("panel.start -> feed.start", "panel.wear_start -> feed.wear_start",
                  "panel.emergency -> feed.emergency", "panel.mfin -> feed.mfin", "feed.m_active -> panel.m_active")


def grinder_feed() -> System:
    """The seed's program on the wheel head: rapid 4.0, rough to 4.2, fine to 4.3, spark-out 1.5 s, return."""
    return System(
        name="grinder_feed",
        description="Grinder: operator panel -> programmable feed -> X (wheel-head infeed) servo",
        components=[
            _component("panel", "OperatorPanel", start_at=0.1),
            _component("feed", "ProgrammableFeed", D1=0.02, D2=0.20, D3=4.0, D4=4.30, D5=0.10,
                       F1=0.02, F2=0.005, F7=10.0, T1=1.5, x_origin=0.0),
            _component("x_axis", "ServoAxis", pos_start=0.0),
        ],
        connections=_wire(*_PANEL_TO_FEED,
                          "feed.x_cmd -> x_axis.pos_cmd", "feed.x_vff -> x_axis.vel_ff",
                          "x_axis.pos -> feed.x_pos", "x_axis.in_position -> feed.x_in_position"),
        stop_time=35.0,
    )


#: Grinder envelope (SPEC 5): reference Y (table), limited X (infeed).
GRINDER_TABLE = [(200.0, -100.0, 250.0),    # dresser
                 (350.0, -100.0, 80.0),     # headstock
                 (800.0, -100.0, 180.0),    # work
                 (1000.0, -100.0, 60.0)]    # tailstock

#: Traverse to the work, approach, grind, spark out, retract, traverse back. EMB retracts X first.
ENVELOPE_PROGRAM = ("M0: Y+D1F7; M1: X+D2F7; M2: X+D3F1; M3: T1; M4: X-D4F7; M5: Y-D1F7; M6: END; "
                    "M41: XF7S1; M42: YF7S1; M43: END; M45: X+D5F2S4; M46: END")


def grinder_envelope() -> System:
    """Programmable feed on X and Y -> area limiter (dresser, headstock, work, tailstock) -> X and Y servos."""
    x0, y0 = 0.0, 100.0
    return System(
        name="grinder_envelope",
        description="Grinder: programmable feed on X and Y -> area limiter -> X and Y servos",
        components=[
            _component("panel", "OperatorPanel", start_at=0.1),
            _component("feed", "ProgrammableFeed", program=ENVELOPE_PROGRAM, wear_address=45,
                       D1=400.0, D2=150.0, D3=20.0, D4=170.0, D5=0.05, F1=2.0, F2=0.005, F7=100.0, T1=1.0,
                       x_origin=x0, y_origin=y0),
            _component("limiter", "AreaLimiter", ref_start=y0, lim_start=x0, predictive=True, use_actual=True,
                       **_table(GRINDER_TABLE)),
            _component("x_axis", "ServoAxis", pos_start=x0),
            _component("y_axis", "ServoAxis", pos_start=y0),
        ],
        connections=_wire(*_PANEL_TO_FEED,
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


def mill_contour() -> System:
    """Contour (0,0) (60,0) (60,40) (20,40) (0,20) (0,0), cutter 0.4 mm larger than nominal, 5 mm/s."""
    path = [(0.0, 0.0), (60.0, 0.0), (60.0, 40.0), (20.0, 40.0), (0.0, 20.0), (0.0, 0.0)]
    points: dict[str, object] = {"n_points": len(path)}
    for i, (x, y) in enumerate(path, start=1):
        points[f"point[{i}].x"], points[f"point[{i}].y"] = x, y
    x0, y0 = 0.0, -10.0
    return System(
        name="mill_contour",
        description="Mill: contour interpolator with cutter compensation -> X and Y servos",
        components=[
            _component("panel", "OperatorPanel", start_at=0.1),
            _component("contour", "ContourInterpolator", closed=True, diameter_delta=0.4, side=-1, feed=5.0,
                       approach_feed=5.0, x_start=x0, y_start=y0, **points),
            _component("x_axis", "ServoAxis", pos_start=x0),
            _component("y_axis", "ServoAxis", pos_start=y0),
        ],
        connections=_wire(
            "panel.start -> contour.start", "panel.feed_hold -> contour.feed_hold",
            "panel.feed_override -> contour.feed_override",
            "contour.x_cmd -> x_axis.pos_cmd", "contour.x_vff -> x_axis.vel_ff",
            "contour.y_cmd -> y_axis.pos_cmd", "contour.y_vff -> y_axis.vel_ff",
            "x_axis.pos -> contour.x_pos", "x_axis.in_position -> contour.x_in_position",
            "y_axis.pos -> contour.y_pos", "y_axis.in_position -> contour.y_in_position",
        ),
        stop_time=42.0,
    )


SYSTEMS: dict[str, Callable[[], System]] = {
    "mill_contour": mill_contour,
    "lathe_roughing": lathe_roughing,
    "lathe_taper": lathe_taper,
    "grinder_feed": grinder_feed,
    "grinder_envelope": grinder_envelope,
}


def get_system(name: str) -> System:
    try:
        return SYSTEMS[name]()
    except KeyError:
        raise SystemDefinitionError(f"unknown system {name!r}; known systems: {', '.join(SYSTEMS)}") from None
