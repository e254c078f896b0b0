"""The mill system: contour interpolator with cutter compensation -> X and Y servos."""

from __future__ import annotations

from ..cosim.ssp import System
from .compose import REPEATS, component, points, wire
from .part import MillPart
from .report import Axes, ContourCycle, Plane, Report

#: The mill's contour, closed, programmed as terminal points.
CONTOUR = [(0.0, 0.0), (60.0, 0.0), (60.0, 40.0), (20.0, 40.0), (0.0, 20.0), (0.0, 0.0)]

REPORT = Report(
    (ContourCycle(contour="contour", x="x_axis", y="y_axis"), Axes(("x_axis", "y_axis")),
     MillPart(contour="contour", x="x_axis", y="y_axis")),
    Plane(horizontal="x_axis", vertical="y_axis", title="contour in the X-Y plane", xlabel="X [mm]",
          ylabel="Y [mm]", path_label="cutter centre (actual)", equal_aspect=True),
    repeats=REPEATS)


def mill_contour() -> System:
    """Contour (0,0) (60,0) (60,40) (20,40) (0,20) (0,0), cutter 0.4 mm larger than nominal, 5 mm/s."""
    x0, y0 = 0.0, -10.0
    return System(
        name="mill_contour",
        description="Mill: contour interpolator with cutter compensation -> X and Y servos",
        components=[
            component("panel", "OperatorPanel", start_at=0.1),
            component("contour", "ContourInterpolator", closed=True, diameter_delta=0.4, side=-1, feed=5.0,
                      approach_feed=5.0, x_start=x0, y_start=y0, **points(CONTOUR)),
            component("x_axis", "ServoAxis", pos_start=x0),
            component("y_axis", "ServoAxis", pos_start=y0),
        ],
        connections=wire(
            "panel.start -> contour.start", "panel.feed_hold -> contour.feed_hold",
            "panel.feed_override -> contour.feed_override",
            "contour.x_cmd -> x_axis.pos_cmd", "contour.x_vff -> x_axis.vel_ff",
            "contour.y_cmd -> y_axis.pos_cmd", "contour.y_vff -> y_axis.vel_ff",
            "x_axis.pos -> contour.x_pos", "x_axis.in_position -> contour.x_in_position",
            "y_axis.pos -> contour.y_pos", "y_axis.in_position -> contour.y_in_position",
        ),
        stop_time=42.0,
    )
