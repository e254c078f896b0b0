"""ncfmu's own exception classes.

Every error a user can cause names the variable, the value and the rule it breaks.
"""

from __future__ import annotations

import re

#: A program line's block number: N (after a block-delete slash) first in the line.
_BLOCK_NUMBER = re.compile(r"\s*/?\s*[Nn]\s*(\d+)")


class NcfmuError(Exception):
    """Base class of every error ncfmu raises on purpose."""


class ConfigError(NcfmuError, ValueError):
    """A parameter (register, setting, table entry, program) breaks a rule.

    Raised before a controller runs; the FMI adapter turns it into ``fmi2Error`` at
    ``exitInitializationMode`` with the message in the FMU log.
    """

    def __init__(self, variable: str, value: object, rule: str):
        self.variable = variable
        self.value = value
        self.rule = rule
        super().__init__(f"{variable} = {value!r}: {rule}")

    def in_words(self) -> str:
        """The refusal as a user reads it (a front end's one line, an FMU's log): the message itself here; a
        program's error says it in a CNC's words (:meth:`ProgramError.in_words`)."""
        return str(self)


class ProgramError(ConfigError):
    """A line of a program parameter breaks its grammar; names the line, the column and the reason."""

    def __init__(self, line_no: int, column: int, text: str, reason: str):
        self.line_no, self.column, self.reason = line_no, column, reason
        super().__init__("program", text, f"line {line_no}, column {column}: {reason}")

    @property
    def block_number(self) -> int | None:
        """The line's block number (its N word, after a block-delete slash), or None."""
        m = _BLOCK_NUMBER.match(str(self.value))
        return int(m.group(1)) if m else None

    @property
    def where(self) -> str:
        """``line 3 (N30)``, as a CNC's alarm names a block (the line alone when it has no N)."""
        n = self.block_number
        return f"line {self.line_no}" + (f" (N{n})" if n is not None else "")

    def cnc_words(self) -> str:
        """``line 3 (N30): G112: not in the subset (polar interpolation)``."""
        return f"{self.where}: {self.reason}"

    def in_words(self) -> str:
        return f"{self.variable}: {self.cnc_words()}"


class ProgramErrors(ProgramError):
    """Every error found in a program, in line order; its line and column are the first one's."""

    def __init__(self, errors: list[ProgramError]):
        self.errors = list(errors)
        first = self.errors[0]
        ConfigError.__init__(self, "program", first.value, "; ".join(e.rule for e in self.errors))
        self.line_no, self.column, self.reason = first.line_no, first.column, first.reason

    @property
    def block_number(self) -> int | None:
        return self.errors[0].block_number

    def cnc_words(self) -> str:
        """Every error, ``line 3 (N30): ...; line 7 (N70): ...``."""
        return "; ".join(e.cnc_words() for e in self.errors)


class SystemDefinitionError(NcfmuError, ValueError):
    """A system (SSP file, connection, instance or variable name) is malformed or unknown."""


class SimulationError(NcfmuError, RuntimeError):
    """An FMU refused a call during a simulation."""

    #: An FMU that refused its parameters at initialisation: what it said, in its own words (its error lines:
    #: ours name the parameter and the rule, a program's line in a CNC's words), without the FMI call and status
    #: the message gives -- the one line a front end shows (the FMU's log keeps both).
    refusal: str = ""


class TerminationRequested(SimulationError):
    """An FMU asked to end the simulation (fmi2Discard with fmi2Terminated, FMI 3.0's terminateSimulation).

    ``instance`` names the FMU, ``time`` where the run ends, ``last_time`` how far the FMU got (its
    fmi2LastSuccessfulTime, FMI 3.0's lastSuccessfulTime; None: it cannot say). The run ends at the start of the
    step the FMU refused, or -- when the FMU made that step whole before it asked, as the Reference-FMUs' Stair
    does -- at the step's end, the step done for every FMU (:meth:`at`)."""

    def __init__(self, instance: str, time: float, detail: str = "", last_time: float | None = None):
        self.instance, self.time, self.detail, self.last_time = instance, time, detail, last_time
        super().__init__(f"{instance} asked to end the simulation at t = {time:.6g} s (fmi2Discard with "
                         f"terminateSimulation){': ' + detail if detail else ''}")

    def at(self, time: float) -> TerminationRequested:
        """The same request, the run ending at ``time``."""
        return TerminationRequested(self.instance, time, self.detail, self.last_time)


class FmuCrashed(SimulationError):
    """An FMU's process died inside one of its calls (a signal such as SIGSEGV, ``abort()``, ``exit()``): a foreign
    FMU runs in a process of its own (:mod:`ncfmu.cosim.isolated`), so the run ends with this error and keeps its
    rows. ``instance`` names the FMU, ``call`` the FMI call it died in, ``time`` the simulated time, ``how`` how its
    process ended."""

    def __init__(self, instance: str, call: str, time: float, how: str):
        self.instance, self.call, self.time, self.how = instance, call, time, how
        super().__init__(f"{instance}: the FMU crashed in {call} at t = {time:.6g} s ({how})")


class SimulationTimeout(SimulationError):
    """A run passed its wall-clock deadline (a sweep's ``--timeout``)."""


class BuildError(NcfmuError, RuntimeError):
    """Building or post-processing an FMU failed."""


def require(condition: bool, variable: str, value: object, rule: str) -> None:
    """Raise :class:`ConfigError` unless ``condition`` holds."""
    if not condition:
        raise ConfigError(variable, value, rule)


class DrawingError(NcfmuError, ValueError):
    """A drawing (``--drawing FILE.dxf``) has no part outline the part check can read: names the file, the entity
    (its type and handle) and the rule."""

    def __init__(self, path: str, entity: str, rule: str):
        self.path, self.entity, self.rule = path, entity, rule
        super().__init__(f"--drawing {path}: {entity + ' ' if entity else ''}{rule}")
