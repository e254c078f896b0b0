"""Operator panel and auxiliary devices: push buttons at given times, MFIN after a delay."""

from pythonfmu import Fmi2Slave

from ncfmu.fmi.adapter import fmu_slave
from ncfmu.controllers.panel import OperatorPanel as Logic


@fmu_slave(Logic)
class OperatorPanel(Fmi2Slave):
    """Operator panel and auxiliary devices: push buttons at given times, MFIN after a delay."""
