"""Units as SSP 1.0 and FMI define them: SI base-unit exponents, a factor and an offset.

A value ``x`` in a unit is ``factor * x + offset`` in the SI unit of its exponents (``kg, m, s, A, K, mol, cd,
rad``). Two units convert into each other when their exponents are equal; a connection between them then
carries ``y = gain * x + offset`` (:func:`conversion`). A unit that only has a name (no definition in the SSD or
the modelDescription) converts only into a unit of the same name.

The definitions come from the SSD's ``ssd:Units`` and from each modelDescription's ``UnitDefinitions`` (a
variable's unit is its own ``unit`` attribute or its ``declaredType``'s).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from ..errors import SystemDefinitionError
from ..ports import parse_integer, parse_real

#: The SI base units of SSP 1.0 / FMI 2.0 ``BaseUnit``, in order.
BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


@dataclass(frozen=True)
class Unit:
    """A named unit; ``exponents`` None when nothing defines it (known by its name only)."""

    name: str
    exponents: tuple[int, ...] | None = None
    factor: float = 1.0
    offset: float = 0.0

    @classmethod
    def of(cls, name: str, exponents: Mapping[str, object], factor: object = 1.0, offset: object = 0.0) -> Unit:
        try:
            # an SSD's attributes are text: read by the one parser of numbers (ASCII decimal)
            exps = tuple(parse_integer(e) if isinstance(e := exponents.get(b, 0) or 0, str) else int(e)  # type: ignore[call-overload]
                         for b in BASE)
            f = _real(factor if factor is not None else 1.0)
            o = _real(offset if offset is not None else 0.0)
        except (TypeError, ValueError):
            raise SystemDefinitionError(f"unit {name!r}: BaseUnit exponents must be whole numbers and factor/offset "
                                        "numbers") from None
        if not (math.isfinite(f) and f != 0 and math.isfinite(o)):
            raise SystemDefinitionError(f"unit {name!r}: factor {f!r} must be finite and not 0, offset finite")
        return cls(name, exps, f, o)

    def dimension(self) -> str:
        """``m.s-1``: the SI exponents in words, for messages; ``?`` when undefined."""
        if self.exponents is None:
            return "?"
        parts = [b if e == 1 else f"{b}{e}" for b, e in zip(BASE, self.exponents) if e]
        return ".".join(parts) or "1"


def _real(value: object) -> float:
    return parse_real(value) if isinstance(value, str) else float(value)  # type: ignore[arg-type]


def unit_from_fmpy(name: str, definitions) -> Unit:
    """``name`` as defined in an fmpy model description's ``unitDefinitions`` (a list of fmpy ``Unit``)."""
    for d in definitions or ():
        if d.name == name and d.baseUnit is not None:
            b = d.baseUnit
            return Unit.of(name, {k: getattr(b, k, 0) for k in BASE}, getattr(b, "factor", 1.0),
                           getattr(b, "offset", 0.0))
    return Unit(name)


def variable_unit(variable) -> str | None:
    """The unit of an fmpy model variable: its own, else its declared type's."""
    unit = getattr(variable, "unit", None)
    if not unit and getattr(variable, "declaredType", None) is not None:
        unit = getattr(variable.declaredType, "unit", None)
    return unit or None


@dataclass(frozen=True)
class Conversion:
    """``y = gain * x + offset`` from the source's unit to the destination's."""

    source: Unit
    target: Unit
    gain: float
    offset: float

    @property
    def identity(self) -> bool:
        return self.gain == 1.0 and self.offset == 0.0

    def __str__(self) -> str:
        text = f"{self.source.name} -> {self.target.name}: x {self.gain:.10g}"
        return text + (f" {'+' if self.offset >= 0 else '-'} {abs(self.offset):.10g}" if self.offset else "")


def conversion(source: Unit, target: Unit) -> Conversion | None:
    """The conversion from ``source`` to ``target``, or None when they are not the same quantity."""
    if source.exponents is None or target.exponents is None:
        return Conversion(source, target, 1.0, 0.0) if source.name == target.name else None
    if source.exponents != target.exponents:
        return None
    if source.factor == target.factor and source.offset == target.offset:
        return Conversion(source, target, 1.0, 0.0)
    gain = source.factor / target.factor
    return Conversion(source, target, gain, (source.offset - target.offset) / target.factor)
