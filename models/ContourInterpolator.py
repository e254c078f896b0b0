"""Contour interpolator with cutter compensation (GB 1,175,423): offset-segment intersection,
DDA interpolation, feed override."""

from pythonfmu import Fmi2Slave

from ncfmu.controllers.contour import ContourInterpolator as Logic
from ncfmu.fmi.adapter import fmu_slave


@fmu_slave(Logic)
class ContourInterpolator(Fmi2Slave):
    """Contour interpolator with cutter compensation (GB 1,175,423)."""
