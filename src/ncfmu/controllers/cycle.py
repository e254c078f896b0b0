"""The NC cycle every controller of servo axes shares, written once.

A cycle controller (the lathe's CutSequencer, the grinder's ProgrammableFeed, the mill's
ContourInterpolator) commands servo axes through motions and must know, as a control does, when a
motion has really ended and when something has gone wrong. What its seed adds (sub-cycles, a program
store, a contour) sits on this skeleton:

- **cycle start** is a push button read for its rising edge (:class:`Button`);
- **inputs are judged every step**: a position input that is NaN, beyond any machine or jumps faster
  than any axis moves, and an override that is not finite, raise the alarm (:meth:`CycleController.judge_inputs`),
  and so does an excess following error, ``|command - actual| > max_following_error``;
- **the alarm latches** and says why once (:meth:`CycleController.latch_alarm`); the controller brings its
  motion to a controlled stop along its path;
- **a motion ends** only when its command has stopped, the servos have had one round trip through the
  master to answer the final command (trusted from the 2nd step after the stop: one step with
  Gauss-Seidel, two with Jacobi), every axis reports in-position AND stands within ``inpos_band`` of the
  controller's *own* command (a move held downstream never counts as done). Waiting longer than
  ``inpos_timeout`` after the command stopped is the in-position alarm (:class:`InPosition`);
- **follow-up**: START after an alarm re-bases the command on the actual position where a stop left them
  more than ``inpos_band`` apart (:func:`follow_up`).

Nothing here knows a system; time enters only through ``dt``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from ..ports import Port, real
from .base import SPEED_LIMIT, Controller, OverrideDial, PositionGuard, finite_inputs, real_param

#: What :meth:`InPosition.judge` says of a motion this step.
MOVING, WAITING, ARRIVED, LATE = 0, 1, 2, 3


def cycle_ports(what: str = "a motion", *names: str) -> tuple[Port, ...]:
    """The parameters of the cycle skeleton, in every cycle controller: the excess-following-error limit, the
    in-position band and timeout (``names``: these only, in this order; default all three). ``what`` names
    the controller's motion in the descriptions. A controller that gains one of them appends it to the END of
    its ports: a port's index is its value reference, which hosts keep."""
    ports = {
        "max_following_error": real("max_following_error", "parameter", 2.0, "mm",
                                    "excess following error alarm: |command - actual position| above this raises "
                                    "alarm", min=0.0, min_exclusive=True),
        "inpos_band": real("inpos_band", "parameter", 0.005, "mm",
                           f"{what} ends only when the actual positions are this close to the controller's own "
                           "command", min=0.0, min_exclusive=True),
        "inpos_timeout": real("inpos_timeout", "parameter", 2.0, "s", "in-position check: alarm when the axes have "
                              "not reached the command this long after it stopped (an axis held downstream)",
                              min=0.0, min_exclusive=True),
    }
    return tuple(ports[n] for n in (names or tuple(ports)))


class Button:
    """A push-button input read for its rising edge."""

    def __init__(self) -> None:
        self.was = False

    def pressed(self, value: object) -> bool:
        now = bool(value)
        edge, self.was = now and not self.was, now
        return edge


class InPosition:
    """Decides when a motion has ended (see the module docstring), one judgement per step.

    Parameters
    ----------
    band : float
        The actual positions must stand this close to the controller's own command, mm.
    timeout : float
        Waiting longer than this after the command stopped is :data:`LATE`, s.
    """

    def __init__(self, band: float, timeout: float) -> None:
        self.band, self.timeout = band, timeout
        self.reset()

    def reset(self) -> None:
        """A new motion begins: nothing counted yet."""
        self.steps = 0          # steps since the command stopped
        self.waited = 0.0       # time waited for the axes since then, s

    def judge(self, dt: float, stopped: bool, in_position: bool, actual: Sequence[float],
              command: Sequence[float]) -> int:
        """:data:`ARRIVED` (and reset), :data:`LATE` (and reset), :data:`WAITING` or :data:`MOVING`."""
        self.steps = self.steps + 1 if stopped else 0
        if self.steps >= 2 and in_position and self.arrived(actual, command):
            self.reset()
            return ARRIVED
        if not stopped:
            return MOVING
        self.waited += dt
        if self.waited > self.timeout:
            self.reset()
            return LATE
        return WAITING

    def arrived(self, actual: Sequence[float], command: Sequence[float]) -> bool:
        return all(abs(a - c) <= self.band for a, c in zip(actual, command))


def follow_up(actual: Mapping[str, float], command: Mapping[str, float], band: float) -> list[str]:
    """The axes where a stop left the actual position more than ``band`` from the command: the command is to be
    re-based there (as an NC does after a stop it did not command)."""
    return [axis for axis in command if abs(actual[axis] - command[axis]) > band]


class CycleController(Controller):
    """Base of the controllers that run cycles on servo axes (:data:`AXES`): the skeleton's parameters,
    state and judgements. A subclass lists :func:`cycle_ports` among its ports, calls
    :meth:`configure_cycle` from ``configure`` and :meth:`reset_cycle` from ``reset``."""

    #: The axes the controller commands, by letter: inputs ``<a>_pos``, ``<a>_in_position``.
    AXES: tuple[str, ...] = ()

    def configure_cycle(self, values: Mapping[str, object]) -> None:
        self.max_following_error = real_param(values, "max_following_error")
        self.inpos_band = real_param(values, "inpos_band")
        self.inpos_timeout = real_param(values, "inpos_timeout")

    def reset_cycle(self) -> None:
        self.alarm = False
        self.start_button = Button()
        self.inpos = InPosition(self.inpos_band, self.inpos_timeout)
        self.positions = PositionGuard(tuple(f"{a}_pos" for a in self.AXES))
        self.override = OverrideDial()

    def actual(self, inputs: Mapping[str, object], axes: Sequence[str] | None = None) -> list[float]:
        """The actual positions of ``axes`` (default: all), from the servo inputs."""
        return [float(inputs[f"{a}_pos"]) for a in (self.AXES if axes is None else axes)]  # type: ignore[arg-type]

    def in_position(self, inputs: Mapping[str, object], axes: Sequence[str] | None = None) -> bool:
        return all(bool(inputs[f"{a}_in_position"]) for a in (self.AXES if axes is None else axes))

    def judge_inputs(self, inputs: Mapping[str, object], dt: float) -> str | None:
        """Why the inputs cannot be used this step (a position NaN, beyond any machine or jumping, an override
        not finite), else None."""
        return self.positions.check(inputs, dt) or finite_inputs(inputs, ("feed_override",))

    def following_error(self, inputs: Mapping[str, object], command: Sequence[float]) -> str | None:
        """The excess-following-error message when ``|command - actual|`` on any axis passes the limit."""
        err = max(abs(c - a) for c, a in zip(command, self.actual(inputs)))
        if err > self.max_following_error:
            return f"excess following error {err:.4f} mm > max_following_error {self.max_following_error:g} mm"
        return None

    def latch_alarm(self, t: float, why: str, consequence: str) -> None:
        """Latch the alarm; the first time, say why and what follows (one log line)."""
        if not self.alarm:
            self.say("error", f"t = {t:.4f} s: {why}; {consequence}")
        self.alarm = True

    def reach_fault(self, inputs: Mapping[str, object], commands: Mapping[str, float]) -> str | None:
        """A restored running cycle: each axis's command within ``max_following_error`` and one step (at
        SPEED_LIMIT) of the actual axis, so no restored state hands a servo a jump (else a message naming it)."""
        if self.positions.last is None:            # nothing judged yet: no actual position to compare with
            return None
        bound = self.max_following_error + SPEED_LIMIT * self.PERIOD
        for axis, command in commands.items():
            off = abs(command - float(inputs[f"{axis}_pos"]))  # type: ignore[arg-type]
            if off > bound:
                return (f"{axis}_cmd = {command!r}: {off:.4g} mm from the actual {axis}_pos, beyond "
                        f"max_following_error = {self.max_following_error:g} mm and one step")
        return None

    def check_state(self, inputs: Mapping[str, object]) -> str | None:
        """A restored state: the in-position check judges with this controller's band and timeout and has
        waited no longer than the timeout (then the rules of :meth:`Controller.check_state`)."""
        why = super().check_state(inputs)
        if why:
            return why
        check = self.inpos
        if (check.band, check.timeout) != (self.inpos_band, self.inpos_timeout):
            return (f"inpos: band {check.band!r}, timeout {check.timeout!r}: not inpos_band = {self.inpos_band:g} mm, "
                    f"inpos_timeout = {self.inpos_timeout:g} s")
        if not (type(check.steps) is int and check.steps >= 0):
            return f"inpos.steps = {check.steps!r}: must be a count >= 0"
        if not 0.0 <= check.waited <= self.inpos_timeout:
            return f"inpos.waited = {check.waited!r}: not within inpos_timeout = {self.inpos_timeout:g} s"
        return None
