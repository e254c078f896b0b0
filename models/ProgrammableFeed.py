"""Grinding-machine programmable feed control (JP S60-43522): program store, rough/fine/spark-out,
wear compensation, emergency return."""

from pythonfmu import Fmi2Slave

from ncfmu.controllers.feed import ProgrammableFeed as Logic
from ncfmu.fmi.adapter import fmu_slave


@fmu_slave(Logic)
class ProgrammableFeed(Fmi2Slave):
    """Grinding-machine programmable feed control (JP S60-43522)."""
