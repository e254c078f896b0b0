"""Straight-line motion with an acceleration-limited, online feed profile.

An NC's interpolator moves all axes of a block together along the straight line, at the block's
vector rate, with an acceleration limit so that the servo never receives a jump. The profile is
computed online, so feed override and feed hold act at once (within the acceleration limit) and the
move still stops exactly at its end point.
"""

from __future__ import annotations

import math

from .geometry import Arc, Element, Point
from .mypyc_compat import mypyc_attr

#: On an arc: tangential and centripetal acceleration as fractions of ``accel`` (as the contour interpolator).
ARC_TANGENTIAL, ARC_CENTRIPETAL = 0.8, 0.55


def stop_speed(room: float, v_old: float, accel: float, dt: float) -> float:
    """Highest end-of-step speed toward a stop point ``room`` ahead from which braking at ``accel`` still
    stops within it, the speed changing linearly within the step (trapezoidal steps):
    ``(v_old + v)/2*dt + v**2/(2*accel) <= room``. 0 when there is no room left."""
    half = 0.5 * accel * dt
    rest = room - 0.5 * max(v_old, 0.0) * dt
    if rest <= 0.0:
        return 0.0
    # the root of v**2 + 2*half*v = 2*accel*rest, written without cancellation (-half + sqrt(...) loses the
    # digits that decide the last step of a stop when half**2 >> 2*accel*rest)
    return 2.0 * accel * rest / (half + math.sqrt(half * half + 2.0 * accel * rest))


@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)
class LinearMove:
    """One straight move in n axes, advanced step by step.

    Parameters
    ----------
    accel : float
        Path acceleration and deceleration limit, mm/s^2.
    """

    def __init__(self, accel: float) -> None:
        self.accel = accel
        self.start_point: tuple[float, ...] = ()
        self.end_point: tuple[float, ...] = ()
        self.unit: tuple[float, ...] = ()
        self.length = 0.0
        self.rate = 0.0
        self.s = 0.0          # path position, mm
        self.v = 0.0          # path velocity at the end of the last step, mm/s
        self.done = True
        self.halting = False  # a controlled stop is under way: decelerate, then end the move where it rests

    def begin(self, start: tuple[float, ...], end: tuple[float, ...], rate: float) -> None:
        """Start a move from ``start`` to ``end`` at vector rate ``rate`` (mm/s), from rest."""
        delta = [b - a for a, b in zip(start, end)]
        self.length = math.sqrt(sum(d * d for d in delta))
        self.start_point, self.end_point = tuple(start), tuple(end)
        self.unit = tuple(d / self.length for d in delta) if self.length > 0 else tuple(0.0 for _ in delta)
        self.rate = rate
        self.s = 0.0
        self.v = 0.0
        self.done = self.length == 0.0
        self.halting = False

    def advance(self, dt: float, scale: float) -> None:
        """Advance by ``dt`` at ``scale`` times the rate (override; 0 for feed hold).

        The speed changes linearly within a step (trapezoidal integration of the path), so the
        position, the velocity feed-forward and its change over the step (the acceleration) agree.
        """
        if self.done:
            self.v = 0.0
            return
        if self.halting:
            scale = 0.0
        a_dt = self.accel * dt
        v_old = self.v
        remaining = self.length - self.s
        room = remaining - 0.5 * v_old * dt
        v_stop = stop_speed(remaining, v_old, self.accel, dt)
        v_target = min(max(self.rate * scale, v_old - a_dt), v_old + a_dt)
        v = max(min(v_target, v_stop), 0.0)
        s = self.s + 0.5 * (v_old + v) * dt
        if s >= self.length - 1e-12 or (v == 0.0 and room <= 1e-12):
            s = self.length
            v = 0.0
            self.done = True
        self.s, self.v = s, v
        if self.halting and v == 0.0 and not self.done:
            self._end_here()

    def position(self) -> tuple[float, ...]:
        if self.done:
            return self.end_point
        s = self.s
        return tuple([p + u * s for p, u in zip(self.start_point, self.unit)])

    def velocity(self) -> tuple[float, ...]:
        v = self.v
        return tuple([u * v for u in self.unit])

    def halt(self) -> None:
        """Controlled stop (alarm, EMB, a blocked move): decelerate along the path at ``accel``, then
        end the move where it comes to rest. The command never steps its velocity; :attr:`done` turns
        true at rest. Already at rest: ends at once."""
        if self.done:
            return
        self.halting = True
        if self.v == 0.0:
            self._end_here()

    @property
    def at_rest(self) -> bool:
        return self.done or self.v == 0.0

    def _end_here(self) -> None:
        here = self.position()
        self.start_point = self.end_point = here
        self.length = self.s = self.v = 0.0
        self.done = True
        self.halting = False


def xz(p: Point) -> tuple[float, float]:
    """A (z, x) point of the geometry as the controller's (x, z)."""
    return (p[1], p[0])


@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)
class ElementMove(LinearMove):
    """:class:`.motion.LinearMove`'s online speed profile along a line or an arc of the (z, x) plane; positions
    and velocities in (x, z). On an arc the tangential acceleration is ``ARC_TANGENTIAL * accel`` and the speed
    at most ``sqrt(ARC_CENTRIPETAL * accel * R)``, so the vector acceleration stays below ``accel``."""

    def __init__(self, accel: float) -> None:
        super().__init__(accel)
        self.full_accel = accel
        self.arc: Arc | None = None

    def begin(self, start: tuple[float, ...], end: tuple[float, ...], rate: float) -> None:
        self.arc = None
        self.accel = self.full_accel
        super().begin(start, end, rate)

    @staticmethod
    def rate_on(element: Element, rate: float, accel: float) -> float:
        """The rate a move along ``element`` runs at: ``rate``, on an arc at most its centripetal cap."""
        if isinstance(element, Arc):
            return min(rate, math.sqrt(ARC_CENTRIPETAL * accel * element.radius))
        return rate

    def begin_element(self, element: Element, rate: float) -> None:
        self.begin(xz(element.start), xz(element.end), rate)
        if isinstance(element, Arc):
            self.arc = element
            self.length = element.length
            self.done = self.length == 0.0
            self.accel = ARC_TANGENTIAL * self.full_accel
            self.rate = self.rate_on(element, rate, self.full_accel)

    def _end_here(self) -> None:
        """Halted on an arc: the move ends where it rests, a straight move of no length from then on."""
        super()._end_here()
        self.arc = None
        self.accel = self.full_accel

    def position(self) -> tuple[float, ...]:
        if self.arc is None or self.done:
            return super().position()
        return xz(self.arc.point(self.s))

    def velocity(self) -> tuple[float, ...]:
        if self.arc is None or self.done:
            return super().velocity()
        tz, tx = self.arc.tangent(self.s)
        return (tx * self.v, tz * self.v)
