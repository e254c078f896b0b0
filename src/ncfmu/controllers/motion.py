"""Straight-line motion with an acceleration-limited, online feed profile.

An NC's interpolator moves all axes of a block together along the straight line, at the block's
vector rate, with an acceleration limit so that the servo never receives a jump. The profile is
computed online, so feed override and feed hold act at once (within the acceleration limit) and the
move still stops exactly at its end point.
"""

from __future__ import annotations

import math


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

    def advance(self, dt: float, scale: float) -> None:
        """Advance by ``dt`` at ``scale`` times the rate (override; 0 for feed hold).

        The speed changes linearly within a step (trapezoidal integration of the path), so the
        position, the velocity feed-forward and its change over the step (the acceleration) agree.
        """
        if self.done:
            self.v = 0.0
            return
        a_dt = self.accel * dt
        v_old = self.v
        remaining = self.length - self.s
        # Highest end-of-step speed from which decelerating at ``accel`` still stops within
        # ``remaining``: (v_old + v)/2*dt + v**2/(2*accel) <= remaining.
        half = 0.5 * a_dt
        room = remaining - 0.5 * v_old * dt
        v_stop = -half + math.sqrt(half * half + 2.0 * self.accel * room) if room > 0 else 0.0
        v_target = min(max(self.rate * scale, v_old - a_dt), v_old + a_dt)
        v = max(min(v_target, v_stop), 0.0)
        s = self.s + 0.5 * (v_old + v) * dt
        if s >= self.length - 1e-12 or (v == 0.0 and room <= 1e-12):
            s = self.length
            v = 0.0
            self.done = True
        self.s, self.v = s, v

    def position(self) -> tuple[float, ...]:
        if self.done:
            return self.end_point
        return tuple(p + u * self.s for p, u in zip(self.start_point, self.unit))

    def velocity(self) -> tuple[float, ...]:
        return tuple(u * self.v for u in self.unit)

    def stop_now(self) -> None:
        """Abort: stay where the command is (used on an alarm)."""
        here = self.position()
        self.start_point = self.end_point = here
        self.length = self.s = self.v = 0.0
        self.done = True
