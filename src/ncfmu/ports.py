"""Ports declared once, as data.

A controller lists its parameters, inputs and outputs as :class:`Port` records. The FMI adapter
registers them with pythonfmu, the builder writes their units, ranges and descriptions into the
modelDescription, the SSP writer uses them for connectors -- nothing else restates them.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Literal, SupportsFloat, SupportsIndex, SupportsInt

PortType = Literal["Real", "Integer", "Boolean", "String"]
Causality = Literal["parameter", "input", "output"]
#: The value of one variable: a Real, Integer, Boolean or String.
Value = float | int | bool | str

#: Units used by the ports, as (name, SI base-unit exponents, factor) for ``UnitDefinitions``.
UNITS: dict[str, dict] = {
    "mm": {"m": 1, "factor": 1e-3},
    "mm/s": {"m": 1, "s": -1, "factor": 1e-3},
    "mm/s2": {"m": 1, "s": -2, "factor": 1e-3},
    "s": {"s": 1},
    "1/s": {"s": -1},
    "rad/s": {"rad": 1, "s": -1},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N.m.s/rad": {"kg": 1, "m": 2, "s": -1, "rad": -1},
    "kg.m2": {"kg": 1, "m": 2},
    "mm/rev": {"m": 1, "rad": -1, "factor": 1e-3 / (2 * math.pi)},
    "rev/min": {"rad": 1, "s": -1, "factor": 2 * math.pi / 60},
    "rev": {"rad": 1, "factor": 2 * math.pi},
    "deg": {"rad": 1, "factor": math.pi / 180},
    "kW": {"kg": 1, "m": 2, "s": -3, "factor": 1e3},
    "1": {},
}

#: Display units offered next to a unit (name, factor, offset) -- mm/min for feeds.
DISPLAY_UNITS: dict[str, list[tuple[str, float]]] = {
    "mm/s": [("mm/min", 60.0)],
}


@dataclass(frozen=True)
class Port:
    """One FMI variable of a controller.

    Parameters
    ----------
    name : str
        FMI name, structured for indexed items (``block[1].Xd``).
    causality : {"parameter", "input", "output"}
    type : {"Real", "Integer", "Boolean", "String"}
    start : float, int, bool or str
        Start value (required for parameters and inputs).
    unit : str, optional
        Unit of a Real (one of :data:`UNITS`).
    description : str
    min, max : float, optional
        Range of legal values, written into the modelDescription.
    allowed : tuple of float, optional
        The only legal values (within ``min``..``max``), e.g. a side of +1 or -1.
    min_exclusive : bool
        ``min`` itself is not legal (a gain or a time constant must be > 0). The modelDescription can
        only say ``min``; the rule text (:meth:`rule`) and :meth:`check` say it exactly.
    variability : str, optional
        ``fixed`` for parameters, ``discrete`` for non-Real ports, ``continuous`` for Real inputs/outputs
        unless given.
    """

    name: str
    causality: Causality
    type: PortType = "Real"
    start: Value | None = None
    unit: str | None = None
    description: str = ""
    min: float | None = None
    max: float | None = None
    variability: str | None = None
    min_exclusive: bool = False
    allowed: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.unit is not None and self.unit not in UNITS:
            raise ValueError(f"port {self.name}: unit {self.unit!r} is not in ncfmu.ports.UNITS")
        if self.causality in ("parameter", "input") and self.start is None:
            raise ValueError(f"port {self.name}: a {self.causality} needs a start value")

    @property
    def fmi_variability(self) -> str:
        if self.variability:
            return self.variability
        if self.causality == "parameter":
            return "fixed"
        return "continuous" if self.type == "Real" else "discrete"

    def rule(self) -> str:
        """The port's range as text, for messages (``must be in (0, 10]``, ``must be in 1..8``)."""
        if self.allowed is not None:
            return "must be one of " + ", ".join(f"{v:+g}" for v in self.allowed)
        if self.type == "Integer" and self.min is not None and self.max is not None:
            return f"must be in {self.min:g}..{self.max:g}"
        lo = None if self.min is None else ("(" if self.min_exclusive else "[") + f"{self.min:g}"
        hi = None if self.max is None else f"{self.max:g}]"
        if lo and hi:
            return f"must be in {lo}, {hi}"
        if lo:
            return f"must be {'>' if self.min_exclusive else '>='} {self.min:g}"
        if hi:
            return f"must be <= {self.max:g}"
        return "must be finite"

    def check(self, value: object) -> Value:
        """The value as the port's type, if it keeps the port's rule; else :class:`~ncfmu.errors.ConfigError`.

        Nothing is rounded: an Integer must be a whole number, a Boolean a bool (or 0/1).
        """
        from .errors import ConfigError
        if self.type == "String":
            if not isinstance(value, str):
                raise ConfigError(self.name, value, "must be text")
            return value
        if self.type == "Boolean":
            if isinstance(value, bool) or value in (0, 1):
                return bool(value)
            raise ConfigError(self.name, value, "must be true or false")
        try:
            x = parse_real(value) if isinstance(value, str) else to_float(value)
        except (TypeError, ValueError):
            raise ConfigError(self.name, value, NUMBER_RULE if isinstance(value, str) else "must be a number") from None
        if not math.isfinite(x):
            raise ConfigError(self.name, value, "must be finite")
        if self.type == "Integer" and x != int(x):
            raise ConfigError(self.name, value, "must be a whole number")
        if ((self.min is not None and (x < self.min or (self.min_exclusive and x == self.min)))
                or (self.max is not None and x > self.max) or (self.allowed is not None and x not in self.allowed)):
            raise ConfigError(self.name, value, self.rule())
        return int(x) if self.type == "Integer" else x

    def default(self) -> Value:
        """The start value, or the type's zero for an output without one."""
        if self.start is not None:
            return self.start
        zero: dict[PortType, Value] = {"Real": 0.0, "Integer": 0, "Boolean": False, "String": ""}
        return zero[self.type]


#: A number as a user writes it, in ASCII only: Python's float() and int() also take any Unicode digit (an
#: Arabic-Indic five runs as 5), underscores between digits and Unicode spaces around -- none of which a number
#: on a command line, in an .ssv file or an input CSV is. inf and nan are numbers here: their rule refuses them
#: with a message naming the variable.
_REAL = re.compile(r"[+-]?(?:(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|inf|infinity|nan)", re.IGNORECASE)
_INTEGER = re.compile(r"[+-]?[0-9]+")
#: The rule of a number written as text, for messages.
NUMBER_RULE = "must be a number in ASCII decimal (digits 0-9, a '.', an exponent e-3)"
_ASCII_BLANKS = " \t\r\n"


def parse_real(text: str) -> float:
    """A Real written as text (ASCII decimal, e.g. ``-0.5``, ``1e-3``, ``inf``); ValueError if it is not one."""
    core = text.strip(_ASCII_BLANKS)
    if not _REAL.fullmatch(core):
        raise ValueError(f"{text!r}: {NUMBER_RULE}")
    return float(core)


def parse_integer(text: str) -> int:
    """An Integer written as text (ASCII digits with an optional sign); ValueError if it is not one."""
    core = text.strip(_ASCII_BLANKS)
    if not _INTEGER.fullmatch(core):
        raise ValueError(f"{text!r}: must be a whole number in ASCII digits 0-9")
    return int(core)


def is_integer_text(text: str) -> bool:
    """Written as a whole number (``12``, ``-3``), not as a Real (``12.0``, ``1e3``)."""
    return bool(_INTEGER.fullmatch(text.strip(_ASCII_BLANKS)))


def parse_text(fmi_type: str, raw: str) -> Value:
    """An FMI/SSP value written as XML text (a start value, an .ssv parameter) as ``fmi_type``; ValueError if
    it is not one (numbers in ASCII decimal; Boolean: ``true``/``false``/``1``/``0``; Enumeration as Integer)."""
    if fmi_type == "Real":
        return parse_real(raw)
    if fmi_type in ("Integer", "Enumeration"):
        return parse_integer(raw)
    if fmi_type == "Boolean":
        if raw not in ("true", "false", "1", "0"):
            raise ValueError(f"{raw!r} is not a Boolean")
        return raw in ("true", "1")
    return raw


def to_float(value: object) -> float:
    """``float(value)`` of a value known only as ``object`` (a parameter or an input as a host set it):
    the same result, and the same TypeError or ValueError, as ``float()``."""
    if isinstance(value, (float, int, str, bytes, bytearray, SupportsFloat, SupportsIndex)):
        return float(value)
    raise TypeError(f"float() argument must be a string or a real number, not '{type(value).__name__}'")


def to_int(value: object) -> int:
    """``int(value)`` of a value known only as ``object``: the same result, and the same TypeError or
    ValueError, as ``int()``."""
    if isinstance(value, (int, float, str, bytes, bytearray, SupportsInt, SupportsIndex)):
        return int(value)
    raise TypeError(f"int() argument must be a string, a bytes-like object or a real number, "
                    f"not '{type(value).__name__}'")


def real(name: str, causality: Causality, start: float | None = None, unit: str | None = None,
         description: str = "", min: float | None = None, max: float | None = None, **kw) -> Port:
    return Port(name, causality, "Real", start, unit, description, min, max, **kw)


def integer(name: str, causality: Causality, start: int | None = None, description: str = "",
            min: float | None = None, max: float | None = None, **kw) -> Port:
    return Port(name, causality, "Integer", start, None, description, min, max, **kw)


def boolean(name: str, causality: Causality, start: bool | None = None, description: str = "", **kw) -> Port:
    return Port(name, causality, "Boolean", start, None, description, **kw)


def string(name: str, causality: Causality, start: str | None = None, description: str = "", **kw) -> Port:
    return Port(name, causality, "String", start, None, description, **kw)
