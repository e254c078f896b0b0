"""The lathe spindle drive that runs inside the SpindleDrive FMU (this Python stepper is its executable
specification; the FMU is its C model).

A digital speed-controlled drive: the commanded speed is ``direction * speed_cmd`` rev/min (a signed
speed with ``direction`` left at +1, or an unsigned speed with the direction apart, as M03 = +1,
M04 = -1, M05 = 0), held over the communication step and limited to ``speed_max``. Every
``substep`` the PI speed loop (:func:`~ncfmu.servo.spindle_model.speed_controller`, gains from
``speed_bandwidth``) samples the speed from the encoder (quantised to ``counts_per_rev``) and
commands a torque limited to ``torque_max`` and, above the base speed, to ``power_max / |speed|``
(a spindle motor's constant-power range), with conditional integration as anti-windup: a large
speed change is a ramp at the acceleration the torque allows, (torque limit - friction) / J, and
the speed runs into its setpoint without winding up. The current loop and the mechanics
(:func:`~ncfmu.servo.spindle_model.spindle_plant`) are discretised exactly over the substep, with
viscous and Coulomb friction (stick at zero speed while the torque stays within ``tau_coulomb``).
``enable`` false: no torque, the spindle coasts. The input ``load_torque`` (a cutting torque) acts
as Coulomb friction does: it opposes the rotation and holds a standing spindle, never turns it.

Outputs: ``speed`` (rev/min, mean over the step, from the encoder), ``at_speed`` (the speed-arrival
signal: ``|speed - commanded| <= max(at_speed_band * |commanded|, at_speed_min)``, the commanded
speed as limited to ``speed_max``), ``torque`` (motor torque), ``power`` (kW, torque times the
step's mean speed), ``limited`` (a torque, power or speed limit acted during the step) and
``revolutions`` (the encoder's angle in revolutions, signed, for threading and feed per revolution).
A non-finite ``speed_cmd``, a ``direction`` other than -1, 0, +1 or a negative or non-finite
``load_torque`` is not acted on: the last good inputs are held and the reason said once.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..controllers.base import Controller
from ..errors import ConfigError, require
from ..ports import boolean, integer, real, to_float
from .parameters import RAD_S_PER_RPM, SpindleParameters


def _model():
    """python-control's models, imported when a spindle is configured (importing control costs ~1 s)."""
    from . import spindle_model
    return spindle_model


class SpindleDrive(Controller):
    MODEL_NAME = "SpindleDrive"
    DESCRIPTION = ("Lathe spindle drive: PI speed loop, current lag, motor + spindle inertia, torque and power "
                   "limits with anti-windup, viscous and Coulomb friction, encoder, speed-arrival signal")
    SEED = ""              # none: a spindle drive of ncfmu's own design (ncfmu.servo.spindle_model)
    STOP_TIME = 2.0
    #: python-control model rebuilt by configure() from the parameters: not part of a saved FMU state.
    DERIVED = ("plant",)
    NATIVE_SOURCE = "native/spindle_model.c"
    NATIVE_HEADERS = ("native/drive_math.h",)
    NATIVE_DEFINED_BY = ("spindle_model.py", "parameters.py", "bode.py")

    PORTS = (
        real("J", "parameter", 0.2, "kg.m2", "inertia of motor + spindle + chuck + workpiece", min=1e-5, max=100.0),
        real("b_visc", "parameter", 0.01, "N.m.s/rad", "viscous friction", min=0.0, max=100.0),
        real("tau_coulomb", "parameter", 1.0, "N.m", "Coulomb friction torque", min=0.0, max=1e12),
        real("torque_max", "parameter", 100.0, "N.m", "motor torque limit", min=0.0, max=1e5, min_exclusive=True),
        real("power_max", "parameter", 15.0, "kW", "motor power limit (constant-power range above the base speed "
             "power_max / torque_max)", min=0.0, max=1e4, min_exclusive=True),
        real("speed_max", "parameter", 4500.0, "rev/min", "spindle speed limit (the command is limited to it)",
             min=0.0, max=1e5, min_exclusive=True),
        real("tau_current", "parameter", 1e-3, "s", "current-loop time constant", min=1e-6, max=0.1),
        real("speed_bandwidth", "parameter", 100.0, "rad/s", "speed-loop crossover (PI zero at a quarter of it)",
             min=0.0, max=1e5, min_exclusive=True),
        integer("counts_per_rev", "parameter", 2 ** 20, "encoder counts per spindle revolution", min=1,
                max=2 ** 30),
        real("at_speed_band", "parameter", 0.05, "1", "speed-arrival band, a fraction of the commanded speed",
             min=0.0, max=1.0),
        real("at_speed_min", "parameter", 10.0, "rev/min", "least width of the speed-arrival band (for small and "
             "zero commands)", min=0.0, max=1e5),
        # Drives close their speed loops every 62-250 us; below 1 us nothing physical is gained.
        real("substep", "parameter", 2.5e-4, "s", "internal sub-step of the digital drive", min=1e-6, max=0.01),
        real("speed_cmd", "input", 0.0, "rev/min", "commanded spindle speed (signed, or its magnitude with "
             "direction)"),
        integer("direction", "input", 1, "direction: +1 as commanded (M03), -1 reversed (M04), 0 stop (M05)"),
        boolean("enable", "input", True, "drive enable (false: no torque, the spindle coasts)"),
        real("speed", "output", None, "rev/min", "actual spindle speed (encoder, mean over the step)"),
        boolean("at_speed", "output", None, "speed-arrival signal: the speed is within the band of the command"),
        real("torque", "output", None, "N.m", "motor torque"),
        real("power", "output", None, "kW", "mechanical power: torque times the step's mean speed"),
        boolean("limited", "output", None, "a torque, power or speed limit acted during the step"),
        real("revolutions", "output", None, "rev", "spindle angle (encoder), signed, in revolutions"),
        real("load_torque", "input", 0.0, "N.m", "load on the spindle (the cutting torque), >= 0: it opposes the "
             "rotation as friction does and cannot turn the spindle"),
    )

    def configure(self, values: Mapping[str, object]) -> None:
        v = {port.name: port.check(values[port.name]) for port in self.ports("parameter")}
        # check() returned each value as its port's type already: these conversions change no value
        self.p = SpindleParameters(J=float(v["J"]), b_visc=float(v["b_visc"]), tau_current=float(v["tau_current"]),
                                   speed_bandwidth=float(v["speed_bandwidth"]))
        self.tau_coulomb = float(v["tau_coulomb"])
        self.torque_max = float(v["torque_max"])
        self.power_max = float(v["power_max"]) * 1e3           # W
        self.speed_max = float(v["speed_max"])
        self.counts_per_rev = int(v["counts_per_rev"])
        self.at_speed_band = float(v["at_speed_band"])
        self.at_speed_min = float(v["at_speed_min"])
        self.substep = float(v["substep"])
        # The speed loop is sampled every substep: a crossover above 0.5 rad per sample is no design.
        require(self.p.speed_bandwidth * self.substep <= 0.5, "speed_bandwidth", self.p.speed_bandwidth,
                f"must be <= 0.5 / substep = {0.5 / self.substep:g} rad/s (the speed loop is sampled every "
                f"substep = {self.substep:g} s)")
        self.design = _model().design(self.p)
        refusal = self.design.refusal(self.p)
        if refusal:
            raise ConfigError(*refusal)
        self.plant = _model().spindle_plant(self.p)
        self.kp, self.ki = self.p.speed_gains
        self.quantum = 2.0 * math.pi / self.counts_per_rev     # rad per encoder count
        self._plant_cache: dict[float, tuple] = {}

    # FMU state: the python-control model is derived from self.p (and cannot be pickled).
    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["plant"] = None
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)

    def reset(self) -> None:
        self.x = [0.0, 0.0, 0.0, 0.0]          # integral (rad), torque (N·m), angle (rad), speed (rad/s)
        self.a_meas = self.a_last = 0.0        # the encoder's angle at the step's end; the last sample taken
        self.command = 0.0                     # the held command, rev/min, signed (before the speed limit)
        self.load = 0.0                        # the held load torque, N·m
        self.limited = False
        self.fault: str | None = None
        self._outputs: dict[str, object] = {}
        self._publish(0.0, 0.0)

    # -- the plant's discretisation, cached per sub-step length -----------------------------------
    def _substeps(self, dt: float) -> int:
        return max(1, math.ceil(dt / self.substep - 1e-9))

    def _plant_coefficients(self, h: float):
        c = self._plant_cache.get(h)
        if c is None:
            if self.plant is None:
                self.plant = _model().spindle_plant(self.p)
            d = _model().discretize(self.plant, h)
            c = self._plant_cache[h] = (tuple(map(tuple, np.asarray(d.A))), tuple(map(tuple, np.asarray(d.B))))
        return c

    # -- stepping -----------------------------------------------------------------------------------
    def _bad_input(self, inputs: Mapping[str, object]) -> str | None:
        cmd, direction = inputs["speed_cmd"], inputs["direction"]
        if not math.isfinite(cmd):  # type: ignore[arg-type]
            return f"input speed_cmd = {cmd!r}: must be finite"
        if direction not in (-1, 0, 1):
            return f"input direction = {direction!r}: must be -1, 0 or 1"
        load = inputs["load_torque"]
        if not (load >= 0.0 and math.isfinite(load)):  # type: ignore[operator, arg-type]
            return f"input load_torque = {load!r}: must be finite and >= 0"
        return None

    def step(self, t: float, dt: float, inputs: Mapping[str, object]) -> dict[str, object]:
        bad = self._bad_input(inputs)
        if bad:
            # Never act on a broken command: hold the last good one, say why once (until a good one comes).
            if self.fault is None:
                self.say("warning", f"t = {t:.4f} s: {bad}; holding the last command")
            self.fault = bad
        else:
            self.fault = None
            self.command = to_float(inputs["direction"]) * to_float(inputs["speed_cmd"])
            self.load = to_float(inputs["load_torque"])
        a0 = self.a_meas
        self._digital(dt, bool(inputs["enable"]))
        return self._publish((self.a_meas - a0) / dt, self.x[1])

    def _setpoint(self) -> tuple[float, bool]:
        """The commanded speed as the drive takes it (rev/min, limited to speed_max) and whether it was limited."""
        limited = abs(self.command) > self.speed_max
        return (math.copysign(self.speed_max, self.command) if limited else self.command), limited

    def _digital(self, dt: float, enabled: bool) -> None:
        n = self._substeps(dt)
        h = dt / n
        ad, bd = self._plant_coefficients(h)
        (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = ad
        (b00, b01), (b10, b11), (b20, b21) = bd
        xi, torque, angle, speed = self.x
        kp, ki, t_max, p_max, q = self.kp, self.ki, self.torque_max, self.power_max, self.quantum
        tc = self.tau_coulomb + self.load        # the load opposes the rotation as Coulomb friction does
        setpoint, limited = self._setpoint()
        w_set = setpoint * RAD_S_PER_RPM
        a_meas = self.a_last
        for _ in range(n):
            a_prev = a_meas
            a_meas = round(angle / q) * q
            if enabled:
                w_meas = (a_meas - a_prev) / h
                e = w_set - w_meas
                t_cmd = kp * e + ki * xi
                # the torque limit, and above the base speed the power limit
                t_lim = t_max if w_meas == 0.0 else min(t_max, p_max / abs(w_meas))
                if abs(t_cmd) > t_lim:
                    # Conditional integration: no windup while the limit acts, so the speed runs into its
                    # setpoint at the end of a ramp without overshooting it by the wound-up integral.
                    t_cmd = math.copysign(t_lim, t_cmd)
                    limited = True
                else:
                    xi += e * h
            else:
                t_cmd, xi = 0.0, 0.0
            # Coulomb friction and load: sliding they oppose the speed; at rest they balance up to their sum.
            if tc == 0.0:
                t_fr = 0.0
            elif speed != 0.0:
                t_fr = math.copysign(tc, speed)
            else:
                t_fr = min(max(torque, -tc), tc)
            torque, angle_n, speed_n = (a00 * torque + a01 * angle + a02 * speed + b00 * t_cmd + b01 * t_fr,
                                        a10 * torque + a11 * angle + a12 * speed + b10 * t_cmd + b11 * t_fr,
                                        a20 * torque + a21 * angle + a22 * speed + b20 * t_cmd + b21 * t_fr)
            if t_fr != 0.0:
                if speed == 0.0 and abs(torque) <= tc:
                    angle_n, speed_n = angle, 0.0          # stick
                elif speed * speed_n < 0.0:
                    # Friction stopped the spindle within the sub-step (re-decided next sub-step); it only
                    # brakes: the spindle stops where a uniform deceleration from its speed takes it.
                    s_stop = speed / (speed - speed_n)     # fraction of the sub-step until the stop
                    angle_n, speed_n = angle + 0.5 * speed * s_stop * h, 0.0
            angle, speed = angle_n, speed_n
        self.x = [xi, torque, angle, speed]
        self.a_last = a_meas           # the last sample the speed loop took
        self.a_meas = round(angle / q) * q
        self.limited = limited

    def _publish(self, w_mean: float, torque: float) -> dict[str, object]:
        out = self._outputs
        speed = w_mean / RAD_S_PER_RPM
        setpoint, _ = self._setpoint()
        out["speed"] = speed
        out["at_speed"] = abs(speed - setpoint) <= max(self.at_speed_band * abs(setpoint), self.at_speed_min)
        out["torque"] = float(torque)
        out["power"] = float(torque) * w_mean * 1e-3
        out["limited"] = self.limited
        out["revolutions"] = self.a_meas / (2.0 * math.pi)
        return out
