"""What every controller shares: ports as data, parameter loading, input checks, a message log.

A controller is plain Python: parameters and state are attributes, ``reset()`` returns it to its
power-on state, ``step(t, dt, inputs) -> outputs`` advances it by ``dt`` seconds. Time enters only
through ``dt`` (``t`` is for messages). Nothing here imports pythonfmu or fmpy.
"""

from __future__ import annotations

import copy
import math
import re
from collections.abc import Mapping
from typing import ClassVar

from ..errors import ConfigError
from ..ports import Port, boolean, real, to_float, to_int
from .mypyc_compat import attributes, mypyc_attr

#: An entry of a counted table: ``block[3].Xd`` (counted by ``n_blocks``).
_TABLE_ENTRY = re.compile(r"(?P<head>[A-Za-z_]\w*)\[(?P<k>\d+)\]\.")


@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)
class Controller:
    """Base class of the controller logic behind every ncfmu FMU.

    Subclasses declare ``PORTS`` (parameters, inputs and outputs, once, as data, each parameter with its
    rule), implement :meth:`configure` (read the checked parameters, check how they combine), :meth:`reset`
    and :meth:`step`.
    """

    #: Model name of the FMU built from this controller.
    MODEL_NAME: ClassVar[str] = ""
    #: One-line description for the modelDescription.
    DESCRIPTION: ClassVar[str] = ""
    #: The document the behaviour comes from.
    SEED: ClassVar[str] = ""
    #: Default communication step (the controller period), s.
    PERIOD: ClassVar[float] = 1e-3
    #: Default stop time of a stand-alone run, s.
    STOP_TIME: ClassVar[float] = 1.0
    PORTS: ClassVar[tuple[Port, ...]] = ()
    #: A model built from C sources instead of a pythonfmu model script: its C file, relative to the class's package
    #: (the class is then the executable specification of the native FMU), and the other files of that package it
    #: is made from. Empty: a Python FMU.
    NATIVE_SOURCE: ClassVar[str] = ""
    NATIVE_DEFINED_BY: ClassVar[tuple[str, ...]] = ()
    #: C headers of that package the native model includes (shipped in the FMU's sources beside it).
    NATIVE_HEADERS: ClassVar[tuple[str, ...]] = ()
    #: The outputs a parameter or input acts on, for one that acts on only some of them (an operator panel's
    #: button time acts on that button alone); one not named here may act on every output.
    ACTS_ON: ClassVar[Mapping[str, tuple[str, ...]]] = {}

    def __init__(self, **parameters: object) -> None:
        self.messages: list[tuple[str, str]] = []
        values = self.default_parameters()
        unknown = sorted(set(parameters) - set(values))
        if unknown:
            raise ConfigError(unknown[0], parameters[unknown[0]],
                              f"not a parameter of {type(self).__name__}")
        values.update(parameters)
        self.configure(self.check_parameters(values))
        self.reset()

    # -- ports ----------------------------------------------------------------------------------
    @classmethod
    def ports(cls, causality: str | None = None) -> tuple[Port, ...]:
        return tuple(p for p in cls.PORTS if causality is None or p.causality == causality)

    @classmethod
    def default_parameters(cls) -> dict[str, object]:
        return {p.name: p.start for p in cls.ports("parameter")}

    @classmethod
    def default_inputs(cls) -> dict[str, object]:
        return {p.name: p.start for p in cls.ports("input")}

    @classmethod
    def check_parameters(cls, values: Mapping[str, object]) -> dict[str, object]:
        """Every parameter by its port's rule (type, range, whole number): one rule per parameter, in one
        place. :meth:`configure` adds only the rules that tie parameters together (a table's order, a
        program's addresses)."""
        return {p.name: p.check(values[p.name]) for p in cls.ports("parameter")}

    def retune(self, values: Mapping[str, object]) -> None:
        """Apply parameters changed during a run (tunable ones): checked as at construction, and all or nothing.

        ``configure()`` stores each value as it reads it and may raise at a later rule, so the values are first
        tried on a copy: a refused change (ConfigError) leaves this controller exactly as it was."""
        checked = self.check_parameters(values)
        copy.deepcopy(self).configure(checked)    # raises for a refused change, this controller untouched
        self.configure(checked)                   # the same values on the same state: every rule holds

    @classmethod
    def unread(cls, values: Mapping[str, object]) -> dict[str, str]:
        """The parameters that the parameter set ``values`` leaves unread, each with why (``reads block[1..2] only
        (n_blocks = 2)``): a setting of one of them changes nothing, and ncfmu says so. Here, the entries
        ``<head>[k].<field>`` of a counted table (a parameter ``n_<head>s``) beyond its count; a controller
        whose program or mode leaves parameters unread adds them."""
        ports = {p.name: p for p in cls.ports("parameter")}
        counts: dict[str, int | None] = {}
        out: dict[str, str] = {}
        for name in ports:
            entry = _TABLE_ENTRY.match(name)
            count_name = f"n_{entry['head']}s" if entry else ""
            if not entry or count_name not in ports:
                continue
            if count_name not in counts:
                try:
                    counts[count_name] = to_int(ports[count_name].check(values.get(count_name,
                                                                                   ports[count_name].start)))
                except ConfigError:          # a count its rule refuses: the run says so
                    counts[count_name] = None
            count = counts[count_name]
            if count is not None and int(entry["k"]) > count:
                out[name] = f"reads {entry['head']}[1..{count}] only ({count_name} = {count})"
        return out

    @classmethod
    def from_parameters(cls, values: Mapping[str, object]) -> Controller:
        """Build from flat FMI parameter names (``block[1].Xd``); unknown names are refused."""
        return cls(**dict(values))

    # -- to implement ---------------------------------------------------------------------------
    def configure(self, values: Mapping[str, object]) -> None:
        """Read and check the parameters; raise :class:`ConfigError` naming the bad one."""
        raise NotImplementedError

    def reset(self) -> None:
        raise NotImplementedError

    def step(self, t: float, dt: float, inputs: Mapping[str, object]) -> dict[str, object]:
        """Advance by ``dt`` seconds; return the outputs (the same dict each time, updated in place)."""
        raise NotImplementedError

    def step_then_count_messages(self, t: float, dt: float, inputs: Mapping[str, object]) -> int:
        """:meth:`step`, then how many messages are queued: what an FMU's binary calls a step, in one call (compiled,
        no Python frame around the step), and it takes the messages only when there are any."""
        self.step(t, dt, inputs)
        return len(self.messages)

    def outputs(self) -> dict[str, object]:
        """The present outputs (valid from ``reset()`` on)."""
        return self._outputs  # type: ignore[attr-defined]

    # -- helpers --------------------------------------------------------------------------------
    def say(self, level: str, text: str) -> None:
        """Queue a message for the FMU log (``level`` is ``info``, ``warning`` or ``error``)."""
        self.messages.append((level, text))

    def take_messages(self) -> list[tuple[str, str]]:
        out, self.messages = self.messages, []
        return out

    # -- a restored state ---------------------------------------------------------------------------
    def check_state(self, inputs: Mapping[str, object]) -> str | None:
        """Judge the values of a state restored into this controller (its types and structure are checked
        already, against a controller freshly built from the same parameters): a message naming the first
        attribute that breaks its rule (``pos[0] = nan: must be finite``), else None. Subclasses add the
        rules of their own registers and call this first."""
        if not all(type(m) is tuple and len(m) == 2 and m[0] in ("info", "warning", "error") and type(m[1]) is str
                   for m in self.messages):
            return "messages: not a list of (info|warning|error, text) pairs"
        input_ports = {p.name: p for p in self.ports("input")}
        for name, value in attributes(self).items():
            if isinstance(value, PositionGuard):
                if not all(n in input_ports and input_ports[n].unit == "mm" for n in value.names):
                    return f"{name}.names = {value.names!r}: not position inputs of {type(self).__name__}"
                if len(set(value.names)) != len(value.names):
                    return f"{name}.names = {value.names!r}: judges an input twice (and another not at all)"
                if value.last is not None:
                    if type(value.last) is not list or len(value.last) != len(value.names):
                        return f"{name}.last = {value.last!r}: not one position per input"
                    for i, x in enumerate(value.last):
                        if type(x) is not float or not abs(x) <= POSITION_LIMIT:
                            return f"{name}.last[{i}] = {x!r}: must be a finite position within {POSITION_LIMIT:g} mm"
            elif isinstance(value, OverrideDial):
                port = input_ports.get(value.name)
                if port is None or value.hi != port.max:
                    return f"{name}: clamps {value.name!r} to 0..{value.hi!r}, not to its input's range"
        return None

    def outputs_fault(self) -> str | None:
        """A restored state's published outputs are what the state itself publishes (else a message)."""
        published = dict(self._outputs)  # type: ignore[attr-defined]
        if self._publish() != published:  # type: ignore[attr-defined]
            return f"_outputs = {published!r}: not what the state publishes"
        return None

    @staticmethod
    def move_fault(move: object, accel: float, rates: set[float], name: str = "move") -> str | None:
        """A restored straight move (:class:`~ncfmu.controllers.motion.LinearMove`) is one its ``begin()`` and
        ``advance()`` can leave: its geometry recomputed from its end points, its path position and speed
        within the move and the rate it was given one of ``rates``."""
        m = attributes(move)
        ends = (m["start_point"], m["end_point"], m["unit"])
        if m["accel"] != accel:
            return f"{name}.accel = {m['accel']!r}: not accel = {accel!r}"
        if len({len(e) for e in ends}) != 1 or not all(type(x) is float for e in ends for x in e):
            return f"{name}: start_point, end_point and unit are not points of one space"
        for end in ("start_point", "end_point"):
            if not all(abs(x) <= POSITION_LIMIT for x in m[end]):
                return f"{name}.{end} = {m[end]!r}: beyond {POSITION_LIMIT:g} mm, no axis is that long"
        delta = [b - a for a, b in zip(m["start_point"], m["end_point"])]
        length = math.sqrt(sum(d * d for d in delta))
        unit = tuple(d / length for d in delta) if length > 0 else tuple(0.0 for _ in delta)
        if m["length"] != length or m["unit"] != unit:
            return f"{name}.length = {m['length']!r}, unit = {m['unit']!r}: not those of its end points"
        if m["rate"] not in rates:
            return f"{name}.rate = {m['rate']!r}: not a rate of this controller"
        if not (0.0 <= m["s"] <= length and 0.0 <= m["v"] <= min(1.5 * m["rate"], SPEED_LIMIT)):
            return f"{name}.s = {m['s']!r}, v = {m['v']!r}: not within the move (length {length!r})"
        if m["done"] and (m["s"] != length or m["v"] != 0.0 or m["halting"]):
            return f"{name}.done = True: with s = {m['s']!r} of {length!r} and v = {m['v']!r}"
        return None


def servo_ports(*axes: tuple[str, float]) -> tuple[Port, ...]:
    """The ports by which a controller drives servo axes: per axis ``(letter, start position)``,
    inputs ``<a>_pos`` and ``<a>_in_position``, outputs ``<a>_cmd`` and ``<a>_vff``."""
    inputs, outputs = [], []
    for a, start in axes:
        A = a.upper()
        inputs += [real(f"{a}_pos", "input", start, "mm", f"actual {A} position from the {A} servo"),
                   boolean(f"{a}_in_position", "input", True, f"{A} servo in-position")]
        outputs += [real(f"{a}_cmd", "output", None, "mm", f"{A} position command"),
                    real(f"{a}_vff", "output", None, "mm/s", f"{A} velocity feed-forward")]
    return (*inputs, *outputs)


# -- parameter reads: the values arrive checked by their ports (Controller.__init__) -------------
def real_param(values: Mapping[str, object], name: str) -> float:
    """A Real parameter, already checked against its port's rule."""
    return to_float(values[name])


def int_param(values: Mapping[str, object], name: str) -> int:
    """An Integer parameter, already checked against its port's rule (a whole number in range)."""
    return to_int(values[name])


def as_float(value: object) -> float:
    """``float(value)``: an input's value as a float. A float (what a host's fmi2SetReal gives) is taken as it is:
    compiled, a type test instead of a call of ``float`` (an interpreted call, costly in every step)."""
    return value if type(value) is float else float(value)  # type: ignore[arg-type]


def input_or(inputs: Mapping[str, object], name: str, default: object) -> object:
    """``inputs.get(name, default)`` (an input added in a later release, read with its default from a caller that
    gives the first release's inputs). Compiled, a dict's own ``get``: no method looked up on a Mapping."""
    if type(inputs) is dict:
        return inputs.get(name, default)
    return inputs.get(name, default)


def finite_inputs(inputs: Mapping[str, object], names: tuple[str, ...]) -> str | None:
    """Return a message naming the first input that is NaN or infinite, else None."""
    for name in names:
        value = inputs[name]
        if not math.isfinite(value):  # type: ignore[arg-type]
            return f"input {name} = {value!r}: must be finite"
    return None


#: No machine axis is this long: a position input beyond it is a broken signal, not a place (mm).
POSITION_LIMIT = 1.0e5
#: No feed axis moves this fast: a position input changing faster between two steps is a broken
#: signal (a wrong connection, a unit error, a host writing garbage), not motion (mm/s).
SPEED_LIMIT = 2000.0


@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)
class PositionGuard:
    """Judges position inputs every step: finite, within ``POSITION_LIMIT``, and no jump beyond
    ``SPEED_LIMIT * dt`` since the last step (the first step after ``reset()`` has nothing to compare)."""

    def __init__(self, names: tuple[str, ...]) -> None:
        self.names = names
        self.last: list[float] | None = None

    def reset(self) -> None:
        self.last = None

    def check(self, inputs: Mapping[str, object], dt: float) -> str | None:
        """Return a message naming the first absurd input (and the rule), else None."""
        # Every step, twice a step in a lathe: one pass judges, a second one keeps the positions in ``last`` (in
        # place: no list made a step), so that ``last`` is untouched when an input is absurd.
        names, last = self.names, self.last
        n = len(names)
        prev = last if last is not None and len(last) == n else None
        reach = SPEED_LIMIT * dt + 1e-9
        jumped = -1
        for i in range(n):
            value = inputs[names[i]]
            # a float (what a host's fmi2SetReal gives) is judged as a float (compiled: a C test, no call)
            if type(value) is float:
                x = value
            elif math.isfinite(value):  # type: ignore[arg-type]
                x = float(value)  # type: ignore[arg-type]
            else:
                return self._absurd(inputs)
            if not abs(x) <= POSITION_LIMIT:                # false for NaN and the infinities too
                return self._absurd(inputs)
            if prev is not None and jumped < 0 and abs(x - prev[i]) > reach:
                jumped = i
        if prev is None:
            prev = self.last = [0.0] * n
        old = prev[jumped] if jumped >= 0 else 0.0
        for i in range(n):
            value = inputs[names[i]]
            prev[i] = as_float(value)
        if jumped >= 0:
            return (f"input {names[jumped]} jumped {old!r} -> {prev[jumped]!r} in one step of {dt:g} s: "
                    f"faster than {SPEED_LIMIT:g} mm/s, no axis moves so")
        return None

    def _absurd(self, inputs: Mapping[str, object]) -> str:
        values = [inputs[n] for n in self.names]
        for name, value in zip(self.names, values):
            if not math.isfinite(value):  # type: ignore[arg-type]
                return f"input {name} = {value!r}: must be finite"
            if abs(value) > POSITION_LIMIT:  # type: ignore[arg-type]
                return f"input {name} = {value!r}: beyond {POSITION_LIMIT:g} mm, no axis is that long"
        raise AssertionError("called for an absurd input only")


@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)
class OverrideDial:
    """A feed-override input: clamped to 0..``hi``; a value outside is said once per excursion."""

    def __init__(self, name: str = "feed_override", hi: float = 1.5) -> None:
        self.name, self.hi = name, hi
        self.outside = False

    def read(self, controller: Controller, t: float, value: float) -> float:
        clamped = min(max(value, 0.0), self.hi)
        if clamped != value and not self.outside:
            controller.say("warning", f"t = {t:.4f} s: input {self.name} = {value!r}: outside 0..{self.hi:g}, "
                                      f"clamped to {clamped:g}")
        self.outside = clamped != value
        return clamped
