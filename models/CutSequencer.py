"""Lathe repetitive-cut sequencer (US 4,017,723): four sub-cycles per pass, passes, blocks, taper."""

from pythonfmu import Fmi2Slave

from ncfmu.controllers.sequencer import CutSequencer as Logic
from ncfmu.fmi.adapter import fmu_slave


@fmu_slave(Logic)
class CutSequencer(Fmi2Slave):
    """Lathe repetitive-cut sequencer (US 4,017,723): four sub-cycles per pass, passes, blocks, taper."""
