"""The served variables as the OPC UA address space shows them: a :class:`Point` per FMU variable, its unit as
a UNECE code, and the check of a client's write against the port's rule (:func:`check_value`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from ..errors import NcfmuError

#: UNECE codes (OPC UA EngineeringUnits, namespace below) of the units our FMUs declare.
UNECE_NAMESPACE = "http://www.opcfoundation.org/UA/units/un/cefact"
UNECE = {"mm": "MMT", "s": "SEC", "mm/s": "C16", "mm/s2": "M41", "1": "C62", "N.m": "NU", "1/s": "1/s",
         "kg.m2": "B32", "rad/s": "2A", "rev/min": "RPM"}


def _unece_id(code: str) -> int:
    """The UnitId of a UNECE common code (OPC UA Part 8: the code's characters packed into an Int32)."""
    if code == "1/s":
        return -1
    value = 0
    for ch in code:
        value = (value << 8) | ord(ch)
    return value


# -- the served variables -------------------------------------------------------------------------
@dataclass(frozen=True)
class Point:
    """One FMU variable as the server shows it."""

    name: str               # INSTANCE.VARIABLE, the NodeId's string
    instance: str
    variable: str
    type: str               # Real, Integer, Boolean, String (Enumeration served as Integer)
    causality: str
    variability: str
    unit: str | None
    description: str
    minimum: float | None
    maximum: float | None

    @property
    def writes(self) -> str | None:
        """``"input"`` (forcing), ``"parameter"`` (a tunable parameter) or None (read-only)."""
        if self.causality == "input":
            return "input"
        if self.causality == "parameter" and self.variability == "tunable":
            return "parameter"
        return None

    def rule(self) -> str:
        low = "" if self.minimum is None else f">= {self.minimum:g}"
        high = "" if self.maximum is None else f"<= {self.maximum:g}"
        return " and ".join(p for p in (low, high) if p) or "finite"


def points_of(slaves: Sequence) -> list[Point]:
    """Every variable of every FMU, in system order, as its modelDescription declares it."""
    return [Point(f"{s.name}.{v.name}", s.name, v.name, "Integer" if v.type == "Enumeration" else v.type,
                  v.causality, v.variability or "continuous", v.unit, v.description or "", v.min, v.max)
            for s in slaves for v in s.variables.values()]


class WriteRefused(NcfmuError):
    """A client's write (or call) that changes nothing; ``status`` is the OPC UA status code's name."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status = status


def check_value(point: Point, value: object) -> object:
    """``value`` (already of the node's OPC UA type) checked against the port's rule, or :class:`WriteRefused`."""
    if point.writes is None:
        what = "an output" if point.causality == "output" else f"a {point.variability} {point.causality}"
        raise WriteRefused("BadNotWritable", f"{point.name} is {what}: not writable")
    if point.type == "Real":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise WriteRefused("BadTypeMismatch", f"{point.name} = {value!r}: must be a Double")
        try:
            x = float(value)
        except OverflowError:        # an integer beyond any double (a JSON body may say 10**400)
            x = math.inf if value > 0 else -math.inf
        if not math.isfinite(x):
            raise WriteRefused("BadOutOfRange", f"{point.name} = {x!r}: must be finite")
        if (point.minimum is not None and x < point.minimum) or (point.maximum is not None and x > point.maximum):
            raise WriteRefused("BadOutOfRange", f"{point.name} = {x!r}: must be {point.rule()}")
        return x
    if point.type == "Integer":
        if isinstance(value, bool) or not isinstance(value, int):
            raise WriteRefused("BadTypeMismatch", f"{point.name} = {value!r}: must be an Int32")
        if (point.minimum is not None and value < point.minimum) or (point.maximum is not None
                                                                      and value > point.maximum):
            raise WriteRefused("BadOutOfRange", f"{point.name} = {value!r}: must be {point.rule()}")
        return int(value)
    if point.type == "Boolean":
        if not isinstance(value, bool):
            raise WriteRefused("BadTypeMismatch", f"{point.name} = {value!r}: must be a Boolean")
        return value
    if not isinstance(value, str):
        raise WriteRefused("BadTypeMismatch", f"{point.name} = {value!r}: must be a String")
    return value
