"""Operator panel and auxiliary devices: push buttons at given times, MFIN after a delay."""

from pythonfmu import Fmi2Slave

from ncfmu.controllers.panel import OperatorPanel as Logic
from ncfmu.fmi.adapter import fmu_slave


@fmu_slave(Logic)
class OperatorPanel(Fmi2Slave):
    """Operator panel and auxiliary devices: push buttons at given times, MFIN after a delay."""
