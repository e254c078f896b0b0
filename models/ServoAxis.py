"""Servo feed axis designed with python-control: position, velocity and current loops, mechanics, friction, limits, encoder."""

from pythonfmu import Fmi2Slave

from ncfmu.fmi.adapter import fmu_slave
from ncfmu.servo.axis import ServoAxis as Logic


@fmu_slave(Logic)
class ServoAxis(Fmi2Slave):
    """Servo feed axis designed with python-control: position, velocity and current loops, mechanics, friction, limits, encoder."""
