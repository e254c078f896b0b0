"""The NC cycle every controller of servo axes shares, written once: its parts and the order of a step.

A cycle controller (the lathe's CutSequencer, the grinder's ProgrammableFeed, the mill's
ContourInterpolator) commands servo axes through motions and must know, as a control does, when a
motion has really ended and when something has gone wrong. :meth:`CycleController.step` owns the order
of every step; what a controller's seed adds (sub-cycles, a program store, a contour) fills in its hooks:

1. **buttons**: every push button is read for its rising edge, every step (:class:`Button`; the hook
   :meth:`~CycleController.read_buttons`: START, and the grinder's START2 and EMB);
2. **judgement**: a position input that is NaN, beyond any machine or jumps faster than any axis moves, and
   an override that is not finite, raise the alarm (:meth:`~CycleController.judge_inputs`); else the
   external alarm input (the area limiter's ``alarm_in``; the hook :meth:`~CycleController.external_alarm`);
   else an excess following error, ``|command - actual| > max_following_error``, judged under the
   controller's policy (:meth:`~CycleController.watching_following_error`: the one policy that differs, and
   why, is written there);
3. **the alarm latches** and says why once (:meth:`~CycleController.latch_alarm`); the controller brings its
   motion to a controlled stop along its path (:meth:`~CycleController.stop`, the hook
   :meth:`~CycleController.halt`);
4. **commands**: START (:meth:`~CycleController.take_commands`) is taken only when the inputs are sane, no
   external alarm is set and the controller is idle; it waits until the motion is at rest, and after an alarm
   it first re-bases the command on the actual position (**follow-up**, :meth:`~CycleController.follow_up`:
   where a stop left them more than ``inpos_band`` apart), then begins the cycle;
5. **advance** (the hook :meth:`~CycleController.advance`): the motion moves at the dial (or to rest after a
   stop); **a motion ends** only when its command has stopped, the servos have had one round trip through
   the master to answer the final command (trusted from the 2nd step after the stop: one step with
   Gauss-Seidel, two with Jacobi), every axis reports in-position AND stands within ``inpos_band`` of the
   controller's *own* command (a move held downstream never counts as done). Waiting longer than
   ``inpos_timeout`` after the command stopped is the in-position alarm (:class:`InPosition`,
   :meth:`~CycleController.arrival`), raised as every alarm is;
6. **publish** the outputs.

Nothing here knows a system; time enters only through ``dt``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

from ..ports import Port, real
from .base import SPEED_LIMIT, Controller, OverrideDial, PositionGuard, as_float, finite_inputs, real_param
from .mypyc_compat import mypyc_attr

#: What :meth:`InPosition.judge` says of a motion this step.
MOVING, WAITING, ARRIVED, LATE = 0, 1, 2, 3

#: The input names ``<axis><suffix>`` of a tuple of axes, by (axes, suffix): built once, not in every step
#: (a name formatted anew is a new string, allocated and hashed again for each lookup).
_AXIS_INPUTS: dict[tuple[tuple[str, ...], str], tuple[str, ...]] = {}


def axis_inputs(axes: Sequence[str], suffix: str) -> tuple[str, ...]:
    """``("x", "z"), "_pos"`` -> ``("x_pos", "z_pos")``."""
    key = (tuple(axes), suffix)
    names = _AXIS_INPUTS.get(key)
    if names is None:
        names = _AXIS_INPUTS[key] = tuple(f"{a}{suffix}" for a in key[0])
    return names


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


@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)
class Button:
    """A push-button input read for its rising edge."""

    def __init__(self) -> None:
        self.was = False

    def pressed(self, value: object) -> bool:
        now = bool(value)
        edge, self.was = now and not self.was, now
        return edge


@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)
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
        band = self.band
        for a, c in zip(actual, command):        # (a loop: a compiled generator costs more than the test)
            if not abs(a - c) <= band:
                return False
        return True


def follow_up(actual: Mapping[str, float], command: Mapping[str, float], band: float) -> list[str]:
    """The axes where a stop left the actual position more than ``band`` from the command: the command is to be
    re-based there (as an NC does after a stop it did not command)."""
    return [axis for axis in command if abs(actual[axis] - command[axis]) > band]


@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)
class CycleController(Controller):
    """Base of the controllers that run cycles on servo axes (:data:`AXES`): the skeleton's parameters,
    state, judgements and the order of a step (:meth:`step`). A subclass lists :func:`cycle_ports` among its
    ports, calls :meth:`configure_cycle` from ``configure`` and :meth:`reset_cycle` from ``reset``, and fills in
    the hooks :meth:`command_point`, :meth:`rebase`, :meth:`halt`, :meth:`take_commands` (or :meth:`begin`),
    :meth:`advance` and ``_publish``."""

    #: The axes the controller commands, by letter: inputs ``<a>_pos``, ``<a>_in_position``.
    AXES: ClassVar[tuple[str, ...]] = ()
    #: The input by which another device raises the alarm (the area limiter's), or "" for none.
    ALARM_INPUT: ClassVar[str] = "alarm_in"
    #: What a stop after an alarm does, as the alarm's log line says it.
    STOP_SAYS: ClassVar[str] = "decelerating to rest, cycle stopped"
    #: What decelerates while a START waits for rest, as the log says it.
    MOTION_SAYS: ClassVar[str] = "the axes are"
    #: Follow-up re-bases the axes that stand apart only (each axis its own feed), else the whole command point.
    FOLLOW_UP_PER_AXIS: ClassVar[bool] = False
    #: Every cycle controller's: the alarm latched, a cycle running.
    alarm: bool
    busy: bool
    #: Within a step, the positions it judged (None between steps).
    _judged: list[float] | None
    #: Not state (fmi/state.py): ``_judged``. A subclass that derives more lists these too.
    DERIVED: ClassVar[tuple[str, ...]] = ("_judged",)

    # -- the order of a step ------------------------------------------------------------------------
    def step(self, t: float, dt: float, inputs: Mapping[str, object]) -> dict[str, object]:
        """One step of the NC cycle, in the order of the module docstring; the hooks are the controller's."""
        edges = self.read_buttons(inputs)
        bad = self.judge_inputs(inputs, dt)
        # the positions just judged are this step's actual positions (read once: :meth:`actual` hands them out)
        self._judged = None if bad else self.positions.last
        try:
            why = bad
            if bad:
                self.stop(t, bad)
            elif self.ALARM_INPUT and inputs[self.ALARM_INPUT]:
                self.external_alarm(t)
            elif self.watching_following_error():
                why = self.following_error(inputs, self.command_point())
                if why:
                    self.stop(t, why)
            self.take_commands(t, inputs, edges, bad, why)
            self.advance(t, dt, inputs, why)
        finally:
            self._judged = None
        return self._publish()

    # -- hooks: what the controller's seed adds ------------------------------------------------------
    def read_buttons(self, inputs: Mapping[str, object]) -> Any:
        """The rising edges of the step (default: START's, a bool); handed to :meth:`take_commands`."""
        return self.start_button.pressed(inputs["start"])

    def _publish(self) -> dict[str, object]:
        """The outputs of the present state (updated in place, returned)."""
        raise NotImplementedError

    def command_point(self) -> list[float]:
        """The controller's own command, one value per axis of :data:`AXES`."""
        raise NotImplementedError

    def rebase(self, actual: Mapping[str, float]) -> None:
        """Follow-up: make ``actual`` (axis -> position) the command of those axes; the motion starts afresh."""
        raise NotImplementedError

    def halt(self) -> None:
        """The controlled stop after an alarm: the motion decelerates along its path; the cycle ends."""
        raise NotImplementedError

    def idle(self) -> bool:
        """No cycle runs: a START may begin one."""
        return not self.busy

    def at_rest(self) -> bool:
        """The motion stands (a START while it still decelerates after a stop is ignored, and said)."""
        return bool(self.move.at_rest)  # type: ignore[attr-defined]

    def begin(self, t: float, edges: Any) -> None:
        """Begin the cycle START asked for (the alarm is cleared, the command followed up)."""
        raise NotImplementedError

    def advance(self, t: float, dt: float, inputs: Mapping[str, object], why: str | None) -> None:
        """Move the motion by one step (at the dial while a cycle runs, to rest after a stop) and judge its
        arrival (:meth:`arrival`); ``why``: the alarm this step's judgement raised, if any."""
        raise NotImplementedError

    def watching_following_error(self) -> bool:
        """Whether this step judges the excess following error. The one policy that differs between the cycle
        controllers, and why:

        - the lathe (CutSequencer) judges always, at rest too: an axis pushed off its command while the
          sequencer stands (a slide held by the limiter after an alarm) keeps the alarm latched until a START
          follows up -- the seed's distance counters watch the axes whatever runs;
        - the grinder (ProgrammableFeed) while a cycle or the emergency return runs, but not while an aborted
          feed decelerates before EMB's return: the emergency return backs out of what held the wheel, and an
          error alarm there would abort the very back-out;
        - the mill (ContourInterpolator) while a contour runs: at rest it commands nothing.

        Default: while a cycle runs."""
        return not self.idle()

    def external_alarm(self, t: float) -> None:
        """The external alarm input is set (no bad input this step): latch the alarm and stop."""
        self.stop(t, f"{self.ALARM_INPUT} (area limiter) is set")

    def take_commands(self, t: float, inputs: Mapping[str, object], edges: Any, bad: str | None,
                      why: str | None) -> None:
        """The operator's commands of this step: START (``edges``) is taken when the inputs are sane, no
        external alarm is set and the controller is :meth:`idle` (see :meth:`start`)."""
        if edges and self.idle() and not bad and not (self.ALARM_INPUT and inputs[self.ALARM_INPUT]):
            self.start(t, inputs, edges)

    # -- the skeleton's parts -------------------------------------------------------------------------
    def stop(self, t: float, why: str) -> None:
        """The alarm: latch it (said once, with :data:`STOP_SAYS`) and bring the motion to a controlled stop."""
        self.latch_alarm(t, why, self.STOP_SAYS)
        self.halt()

    def start(self, t: float, inputs: Mapping[str, object], edges: Any) -> None:
        """A START taken: ignored (and said) while the motion decelerates; after an alarm, clear it and follow
        up; then :meth:`begin`."""
        if not self.at_rest():
            self.say("warning", f"t = {t:.4f} s: start ignored: {self.MOTION_SAYS} still decelerating")
            return
        if self.alarm:
            self.say("info", f"t = {t:.4f} s: alarm cleared by start")
            self.follow_up(t, inputs)
        self.alarm = False
        self.begin(t, edges)

    def follow_up(self, t: float, inputs: Mapping[str, object]) -> None:
        """Re-base the command on the actual position where a stop left them more than ``inpos_band`` apart (an
        axis held or lagging when the alarm came), as an NC does after a stop it did not command: the axes
        apart only (:data:`FOLLOW_UP_PER_AXIS`) or the whole command point; said once."""
        actual = dict(zip(self.AXES, self.actual(inputs)))
        command = dict(zip(self.AXES, self.command_point()))
        apart = follow_up(actual, command, self.inpos_band)
        if not apart:
            return
        axes = apart if self.FOLLOW_UP_PER_AXIS else self.AXES
        moved = ", ".join(f"{a.upper()} {command[a]:.4f} -> {actual[a]:.4f}" for a in axes)
        self.say("info", f"t = {t:.4f} s: follow-up: command re-based on the actual position ({moved})")
        self.rebase({a: actual[a] for a in axes})

    def arrival(self, t: float, dt: float, stopped: bool, inputs: Mapping[str, object],
                axes: Sequence[str] | None = None) -> bool:
        """One in-position judgement of the motion on ``axes`` (default all) against the controller's own
        command: True when it has ended; :data:`LATE` is the in-position alarm (:meth:`stop`)."""
        if axes is None:                             # (all axes: the input names configured, not looked up)
            axes, target = self.AXES, self.command_point()
            actual, in_position = self.actual(inputs), self.in_position(inputs)
        else:
            command = dict(zip(self.AXES, self.command_point()))
            target = [command[a] for a in axes]
            actual, in_position = self.actual(inputs, axes), self.in_position(inputs, axes)
        judged = self.inpos.judge(dt, stopped, in_position, actual, target)
        if judged == LATE:
            if len(axes) == 1:
                where = f"{axes[0].upper()} stands at {actual[0]:.4f}, not at the command {target[0]:.4f}"
            else:
                where = (f"the axes stand at ({', '.join(f'{p:.4f}' for p in actual)}), not at the command "
                         f"({', '.join(f'{c:.4f}' for c in target)})")
            self.stop(t, f"in-position check: {where}, {self.inpos_timeout:g} s after it stopped (held downstream?)")
        return judged == ARRIVED

    def configure_cycle(self, values: Mapping[str, object]) -> None:
        self.max_following_error = real_param(values, "max_following_error")
        self.inpos_band = real_param(values, "inpos_band")
        self.inpos_timeout = real_param(values, "inpos_timeout")
        # the input names every step reads, once (configured: a restored state must hold these very names)
        self._pos_inputs = axis_inputs(self.AXES, "_pos")
        self._in_position_inputs = axis_inputs(self.AXES, "_in_position")

    def reset_cycle(self) -> None:
        self.alarm = False
        self.start_button = Button()
        self.inpos = InPosition(self.inpos_band, self.inpos_timeout)
        self.positions = PositionGuard(tuple(f"{a}_pos" for a in self.AXES))
        self._judged = None
        self.override = OverrideDial()

    def actual(self, inputs: Mapping[str, object], axes: Sequence[str] | None = None) -> list[float]:
        """The actual positions of ``axes`` (default: all), from the servo inputs (within a step, those the step
        judged: the same values, not read again; the list is not to be changed)."""
        if axes is None and self._judged is not None:
            return self._judged
        names = self._pos_inputs if axes is None else axis_inputs(axes, "_pos")
        return [as_float(inputs[n]) for n in names]

    def in_position(self, inputs: Mapping[str, object], axes: Sequence[str] | None = None) -> bool:
        for name in self._in_position_inputs if axes is None else axis_inputs(axes, "_in_position"):
            if not inputs[name]:
                return False
        return True

    def judge_inputs(self, inputs: Mapping[str, object], dt: float) -> str | None:
        """Why the inputs cannot be used this step (a position NaN, beyond any machine or jumping, an override
        not finite), else None."""
        return self.positions.check(inputs, dt) or finite_inputs(inputs, ("feed_override",))

    def following_error(self, inputs: Mapping[str, object], command: Sequence[float]) -> str | None:
        """The excess-following-error message when ``|command - actual|`` on any axis passes the limit."""
        err = -1.0                                   # (max() of a generator, as a loop: the same first maximum)
        for c, a in zip(command, self.actual(inputs)):
            off = abs(c - a)
            if off > err:
                err = off
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
        """A restored state: the position guard judges the axes' position inputs, in their order (a step's
        :meth:`actual` positions are those it judged); the in-position check judges with this controller's band
        and timeout and has waited no longer than the timeout (then the rules of :meth:`Controller.check_state`)."""
        why = super().check_state(inputs)
        if why:
            return why
        if self.positions.names != self._pos_inputs:
            return f"positions.names = {self.positions.names!r}: not the position inputs {self._pos_inputs!r}"
        check = self.inpos
        if (check.band, check.timeout) != (self.inpos_band, self.inpos_timeout):
            return (f"inpos: band {check.band!r}, timeout {check.timeout!r}: not inpos_band = {self.inpos_band:g} mm, "
                    f"inpos_timeout = {self.inpos_timeout:g} s")
        if not (type(check.steps) is int and check.steps >= 0):
            return f"inpos.steps = {check.steps!r}: must be a count >= 0"
        if not 0.0 <= check.waited <= self.inpos_timeout:
            return f"inpos.waited = {check.waited!r}: not within inpos_timeout = {self.inpos_timeout:g} s"
        return None
