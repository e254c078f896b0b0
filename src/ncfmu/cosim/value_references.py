"""Value references of a foreign FMU's variables: shared only by aliases, as FMI permits.

Two variables with one value reference are one value in the FMU. FMI allows that for aliases -- the same type,
and the same kind of causality (a local alias of an output, a parameter under two names) -- and nowhere else: an
input that shares its value reference with an output is written by the host and read back as the output (the
master would feed the plant's command into its own position). Where a value reference lives differs: FMI 3.0 has
one for all types (a Float64 and an Int32 on one value reference collide; fmpy's validation refuses duplicates
not declared ``<Alias>``), FMI 2.0 one per base type (section 2.2.7: a Real and a Boolean may both be value
reference 0, as the fmi2GetReal and fmi2GetBoolean calls keep them apart; Integer and Enumeration share one). FMI
2.0 declares no aliases, so the check is here, at load (:class:`~ncfmu.cosim.fmu.UnpackedFmu`), for both versions.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from ..errors import SystemDefinitionError

#: Causalities whose variables may alias each other: one value, set by the host (input), fixed or tuned by it
#: (parameter), computed by the FMU (output, local, calculatedParameter), or the time.
CAUSALITY_CLASS = {"input": "input", "parameter": "parameter", "structuralParameter": "parameter",
                   "output": "computed", "local": "computed", "calculatedParameter": "computed",
                   "independent": "independent"}


#: FMI 2.0's value references, one set per base type (an Enumeration is read and written as an Integer).
FMI2_NAMESPACE = {"Real": "Real", "Integer": "Integer", "Enumeration": "Integer", "Boolean": "Boolean",
                  "String": "String"}


def check_value_references(fmu: str, variables: Iterable[Any], fmi3: bool) -> None:
    """Refuse (SystemDefinitionError naming both variables and the value reference) two variables of ``fmu`` (the
    FMU's file name, for the message) that share a value reference and differ in type or in causality class
    (:data:`CAUSALITY_CLASS`); in FMI 2.0 (``fmi3`` false) only variables whose types share their value references
    (:data:`FMI2_NAMESPACE`) can. ``variables``: fmpy's ModelVariables (name, type, causality, valueReference)."""
    first: dict[tuple[str, int], Any] = {}
    clashes = []
    for v in variables:
        space = "" if fmi3 else FMI2_NAMESPACE.get(v.type, v.type)
        seen = first.setdefault((space, v.valueReference), v)
        if seen is v:
            continue
        kind, seen_kind = CAUSALITY_CLASS.get(v.causality, v.causality), CAUSALITY_CLASS.get(seen.causality,
                                                                                              seen.causality)
        if v.type != seen.type or kind != seen_kind:
            clashes.append(f"variables {seen.name} ({seen.causality} {seen.type}) and {v.name} ({v.causality} "
                           f"{v.type}) share value reference {v.valueReference}")
    if clashes:
        raise SystemDefinitionError(f"{fmu}: {'; '.join(clashes)}: only aliases may share a value reference (the "
                                    "same type and causality, e.g. a local alias of an output)")
