"""The parameters of one feed axis, as plain data (no python-control: importing it is cheap)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class AxisParameters:
    """Physical and control parameters of one feed axis (the defaults: a mid-size feed axis).

    Attributes
    ----------
    Kv : float
        Position-loop gain, 1/s.
    kff : float
        Velocity feed-forward factor (1.0: full feed-forward).
    kaff : float
        Acceleration (torque) feed-forward factor (1.0: the inertia torque of the commanded acceleration).
    J : float
        Motor + screw + load inertia referred to the motor, kg·m².
    pitch : float
        Ball-screw lead, mm/rev.
    b_visc : float
        Viscous friction, N·m·s/rad.
    tau_current : float
        Current (torque) loop time constant, s.
    vel_bandwidth : float
        Velocity-loop crossover, rad/s; the PI zero sits at a quarter of it.
    """

    Kv: float = 30.0
    kff: float = 1.0
    kaff: float = 1.0
    J: float = 2.5e-3
    pitch: float = 10.0
    b_visc: float = 1e-3
    tau_current: float = 0.5e-3
    vel_bandwidth: float = 400.0

    @property
    def rad_per_mm(self) -> float:
        """Motor angle per millimetre of travel, rad/mm."""
        return 2.0 * math.pi / self.pitch

    @property
    def torque_per_acceleration(self) -> float:
        """Inertia torque per mm/s² of axis acceleration, N·m/(mm/s²)."""
        return self.J * self.rad_per_mm

    @property
    def velocity_gains(self) -> tuple[float, float]:
        """PI gains (Kp in N·m/(mm/s), Ki in N·m/mm) for the crossover ``vel_bandwidth``."""
        kp = self.J * self.rad_per_mm * self.vel_bandwidth
        return kp, kp * self.vel_bandwidth / 4.0


#: rad/s per rev/min
RAD_S_PER_RPM = 2.0 * math.pi / 60.0


@dataclass(frozen=True)
class SpindleParameters:
    """Physical and control parameters of a lathe spindle drive's speed loop (the defaults: a mid-size CNC lathe,
    15 kW, motor and spindle coupled 1:1).

    Attributes
    ----------
    J : float
        Motor + spindle + chuck + workpiece inertia, kg·m².
    b_visc : float
        Viscous friction (bearings, belt), N·m·s/rad.
    tau_current : float
        Current (torque) loop time constant, s.
    speed_bandwidth : float
        Speed-loop crossover, rad/s; the PI zero sits at a quarter of it.
    """

    J: float = 0.2
    b_visc: float = 0.01
    tau_current: float = 1e-3
    speed_bandwidth: float = 100.0

    @property
    def speed_gains(self) -> tuple[float, float]:
        """PI gains (Kp in N·m/(rad/s), Ki in N·m/rad) for the crossover ``speed_bandwidth``."""
        kp = self.J * self.speed_bandwidth
        return kp, kp * self.speed_bandwidth / 4.0
