"""Operating-area limiter (JP S61-33202): stepped, region-dependent limits; blocks only the offending direction."""

from pythonfmu import Fmi2Slave

from ncfmu.controllers.limiter import AreaLimiter as Logic
from ncfmu.fmi.adapter import fmu_slave


@fmu_slave(Logic)
class AreaLimiter(Fmi2Slave):
    """Operating-area limiter (JP S61-33202): stepped, region-dependent limits; blocks only the offending direction."""
