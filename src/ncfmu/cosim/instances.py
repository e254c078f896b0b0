"""The slave of one instance of an unpacked FMU, by its FMI version: above both FMI modules (:mod:`.fmu` for FMI
2.0, :mod:`.fmu3` for 3.0), which know nothing of each other's slave."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .fmu import FmuSlave, UnpackedFmu

if TYPE_CHECKING:
    from .fmu3 import Fmu3Slave

__all__ = ["make_slave"]


def make_slave(unpacked: UnpackedFmu, instance_name: str) -> FmuSlave | Fmu3Slave:
    """The slave of one instance of ``unpacked``: :class:`FmuSlave` for FMI 2.0, :class:`Fmu3Slave` for 3.0."""
    if unpacked.fmi3:
        from .fmu3 import Fmu3Slave  # fmpy.fmi3 is loaded only for an FMI 3.0 FMU
        return Fmu3Slave(unpacked, instance_name)
    return FmuSlave(unpacked, instance_name)
