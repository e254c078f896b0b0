"""The servo-axis stepper that runs inside the ServoAxis FMU.

Two modes:

Fine interpolation, as a drive in cyclic-position mode does: ``pos_cmd`` is the setpoint for the end
of the communication step, and every sub-step moves the command linearly from the previous setpoint
towards it; ``vel_ff`` is held over the step (it is the slope of that ramp when it comes from an
interpolator) and its change over the step gives the acceleration feed-forward (torque = kaff·J·a).
So a position staircase from a 1 ms controller reaches the loops as a ramp, and the velocity loop
does not have to build up an error to produce the inertia torque.

- ``ideal = true``: the linear closed loop of :func:`~ncfmu.servo.model.servo_axis`, discretised
  exactly (zero-order hold) at ``substep``, fed with the fine-interpolated command -- it reproduces
  ``control.forced_response`` of that discretised model (and, for inputs constant over the run, of
  the continuous model);
- ``ideal = false``: a digital drive. Position and velocity loops are sampled every ``substep``
  (encoder quantised to ``counts_per_rev``, speed command limited to ``speed_max``, torque command
  limited to ``torque_max`` with conditional integration as anti-windup); the current loop and the
  mechanics (:func:`~ncfmu.servo.model.drive_plant`) are discretised exactly over the substep, with
  Coulomb friction (stick at zero speed while the torque stays within ``tau_coulomb``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..controllers.base import Controller, finite_inputs
from ..errors import ConfigError, require
from ..ports import boolean, integer, real, to_float
from .parameters import AxisParameters


def _model():
    """python-control's models, imported when an axis is configured (importing control costs ~1 s, and
    the system definitions, the master and the sweep workers only need the ports)."""
    from . import model
    return model


class ServoAxis(Controller):
    MODEL_NAME = "ServoAxis"
    DESCRIPTION = ("Servo feed axis: P position loop with velocity feed-forward, PI velocity loop, current lag, "
                   "motor + ball screw + load, friction, torque/speed limits, encoder, in-position band")
    SEED = ""              # none: a feed axis of ncfmu's own design (ncfmu.servo.model)
    STOP_TIME = 1.0
    #: python-control models rebuilt by configure() from the parameters: not part of a saved FMU state.
    DERIVED = ("linear", "plant")
    #: The native FMU's C model, relative to this package (ncfmu.servo); it is built from that, not from Python.
    NATIVE_SOURCE = "native/servo_model.c"
    NATIVE_HEADERS = ("native/drive_math.h",)
    #: The other files of this package the native FMU is made from (its design; its documentation's Bode plot).
    NATIVE_DEFINED_BY = ("model.py", "bode.py")

    # The ranges are physical (a machine-tool feed axis) and keep the discretisation well conditioned:
    # a parameter outside them is refused naming itself, not a derived quantity.
    PORTS = (
        real("Kv", "parameter", 30.0, "1/s", "position-loop gain", min=0.0, max=1e4, min_exclusive=True),
        real("kff", "parameter", 1.0, "1", "velocity feed-forward factor", min=0.0, max=2.0),
        real("kaff", "parameter", 1.0, "1", "acceleration (torque) feed-forward factor", min=0.0, max=2.0),
        real("J", "parameter", 2.5e-3, "kg.m2", "inertia of motor + screw + load, referred to the motor",
             min=1e-7, max=10.0),
        real("pitch", "parameter", 10.0, "mm/rev", "ball-screw lead", min=0.1, max=1000.0),
        real("b_visc", "parameter", 1e-3, "N.m.s/rad", "viscous friction", min=0.0, max=100.0),
        real("tau_coulomb", "parameter", 0.1, "N.m", "Coulomb friction torque", min=0.0, max=1e12),
        real("torque_max", "parameter", 12.0, "N.m", "motor torque limit", min=0.0, max=1e5, min_exclusive=True),
        real("speed_max", "parameter", 3000.0, "rev/min", "motor speed limit", min=0.0, max=1e5,
             min_exclusive=True),
        real("tau_current", "parameter", 0.5e-3, "s", "current-loop time constant", min=1e-6, max=0.1),
        real("vel_bandwidth", "parameter", 400.0, "rad/s", "velocity-loop crossover (PI zero at a quarter of it)",
             min=0.0, max=1e5, min_exclusive=True),
        integer("counts_per_rev", "parameter", 2 ** 20, "encoder counts per motor revolution", min=1, max=2 ** 30),
        real("inpos_band", "parameter", 0.005, "mm", "in-position band on |pos_cmd - pos|", min=0.0, max=1e3,
             min_exclusive=True),
        real("pos_start", "parameter", 0.0, "mm", "initial axis position", min=-1e5, max=1e5),
        # Drives close their loops every 31-125 us; below 1 us nothing physical is gained and a 1 ms
        # step would cost over a thousand sub-steps.
        real("substep", "parameter", 1e-4, "s", "internal sub-step of the digital drive", min=1e-6, max=0.01),
        boolean("ideal", "parameter", False, "true: linear model only (no limits, Coulomb friction, quantisation)"),
        real("pos_cmd", "input", 0.0, "mm", "position command"),
        real("vel_ff", "input", 0.0, "mm/s", "velocity feed-forward"),
        boolean("enable", "input", True, "drive enable (false: no torque)"),
        real("pos", "output", None, "mm", "actual position (encoder)"),
        real("vel", "output", None, "mm/s", "actual velocity (mean over the step)"),
        real("following_error", "output", None, "mm", "pos_cmd - pos"),
        boolean("in_position", "output", None, "|following_error| <= inpos_band"),
        real("torque", "output", None, "N.m", "motor torque"),
        boolean("limited", "output", None, "a torque or speed limit acted during the step"),
    )

    def configure(self, values: Mapping[str, object]) -> None:
        v = {port.name: port.check(values[port.name]) for port in self.ports("parameter")}
        # check() returned each value as its port's type already: these conversions change no value
        self.p = AxisParameters(Kv=float(v["Kv"]), kff=float(v["kff"]), kaff=float(v["kaff"]), J=float(v["J"]),
                                pitch=float(v["pitch"]), b_visc=float(v["b_visc"]),
                                tau_current=float(v["tau_current"]), vel_bandwidth=float(v["vel_bandwidth"]))
        self.tau_coulomb = float(v["tau_coulomb"])
        self.torque_max = float(v["torque_max"])
        self.speed_max = float(v["speed_max"])
        self.counts_per_rev = int(v["counts_per_rev"])
        self.inpos_band = float(v["inpos_band"])
        self.pos_start = float(v["pos_start"])
        self.substep = float(v["substep"])
        self.ideal = bool(v["ideal"])
        # The velocity loop is sampled every substep: a crossover above 0.5 rad per sample is no design.
        require(self.p.vel_bandwidth * self.substep <= 0.5, "vel_bandwidth", self.p.vel_bandwidth,
                f"must be <= 0.5 / substep = {0.5 / self.substep:g} rad/s (the velocity loop is sampled every "
                f"substep = {self.substep:g} s)")
        self.design = _model().design(self.p)
        refusal = self.design.refusal(self.p)
        if refusal:
            raise ConfigError(*refusal)
        self.linear = _model().servo_axis(self.p)
        self.plant = _model().drive_plant(self.p)
        self.kp, self.ki = self.p.velocity_gains
        self.v_max = self.speed_max * self.p.pitch / 60.0       # mm/s
        self.quantum = self.p.pitch / self.counts_per_rev       # mm per encoder count
        self._ideal_cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._plant_cache: dict[float, tuple] = {}

    # FMU state: the python-control models are derived from self.p (and cannot be pickled); the
    # state keeps the parameters, the discretisation caches and the loop states.
    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["linear"] = state["plant"] = None
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)

    def _models(self):
        if self.linear is None:
            self.linear, self.plant = _model().servo_axis(self.p), _model().drive_plant(self.p)
        return self.linear, self.plant

    def reset(self) -> None:
        self.x = np.array([0.0, 0.0, self.pos_start, 0.0])   # integral, torque, pos, vel
        self._u = np.zeros(4)                                  # input vector of the ideal step, reused
        self.p_meas = self.p_last = self._quantise(self.pos_start)
        self.limited = False
        self.fault: str | None = None
        self.pos_cmd = self.cmd_prev = self.pos_start
        self.vel_ff = self.vff_prev = 0.0
        self._outputs: dict[str, object] = {}
        self._publish(self.pos_start, 0.0, 0.0)

    # -- discretisations, cached per step length ------------------------------------------------
    def _ideal_matrices(self, dt: float):
        """The communication step as one linear map ``x+ = F x + G [cmd_prev, cmd, vff_prev, vff]``.

        Composed from the ZOH sub-steps with the fine-interpolated command, so it equals stepping
        the substeps one by one (to rounding) at the cost of one product.
        """
        m = self._ideal_cache.get(dt)
        if m is None:
            n = self._substeps(dt)
            d = _model().discretize(self._models()[0], dt / n)
            ad, bd = np.asarray(d.A), np.asarray(d.B)
            f = np.eye(4)
            g = np.zeros((4, 4))
            for i in range(n):
                w = (i + 1) / n   # setpoints at the end of sub-step i, linear between cycles
                u = np.array([[1 - w, w, 0.0, 0.0],                 # pos_cmd
                              [0.0, 0.0, 1 - w, w],                 # vel_ff
                              [0.0, 0.0, -1.0 / dt, 1.0 / dt]])     # acc_ff
                f, g = ad @ f, ad @ g + bd @ u
            m = self._ideal_cache[dt] = (f, g)
        return m

    def _substeps(self, dt: float) -> int:
        return max(1, math.ceil(dt / self.substep - 1e-9))

    def _plant_coefficients(self, h: float):
        c = self._plant_cache.get(h)
        if c is None:
            d = _model().discretize(self._models()[1], h)
            c = self._plant_cache[h] = (tuple(map(tuple, np.asarray(d.A))), tuple(map(tuple, np.asarray(d.B))))
        return c

    def _quantise(self, pos: float) -> float:
        if self.ideal:
            return pos
        return round(pos / self.quantum) * self.quantum

    # -- stepping -------------------------------------------------------------------------------
    def step(self, t: float, dt: float, inputs: Mapping[str, object]) -> dict[str, object]:
        bad = finite_inputs(inputs, ("pos_cmd", "vel_ff"))
        if bad:
            # Never act on a NaN: hold the last good command, say why once.
            if self.fault != bad:
                self.say("error", f"t = {t:.4f} s: {bad}; holding the last command")
            self.fault = bad
        self.cmd_prev, self.vff_prev = self.pos_cmd, self.vel_ff
        if not bad:
            self.fault = None
            self.pos_cmd, self.vel_ff = to_float(inputs["pos_cmd"]), to_float(inputs["vel_ff"])
        p0 = self.p_meas
        if self.ideal and inputs["enable"]:
            f, g = self._ideal_matrices(dt)
            u = self._u
            u[0], u[1], u[2], u[3] = self.cmd_prev, self.pos_cmd, self.vff_prev, self.vel_ff
            self.x = f @ self.x + g @ u
            self.p_meas = self.x[2]
            self.limited = False
        else:
            self._digital(dt, bool(inputs["enable"]))
        vel = self.x[3] if self.ideal else (self.p_meas - p0) / dt
        return self._publish(self.p_meas, vel, self.x[1])

    def _digital(self, dt: float, enabled: bool) -> None:
        n = self._substeps(dt)
        h = dt / n
        ad, bd = self._plant_coefficients(h)
        (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = ad
        (b00, b01), (b10, b11), (b20, b21) = bd
        xi, torque, pos, vel = (float(v) for v in self.x)
        kv, kff, kp, ki = self.p.Kv, self.p.kff, self.kp, self.ki
        v_max, t_max, tc = self.v_max, self.torque_max, self.tau_coulomb
        cmd0, d_cmd = self.cmd_prev, (self.pos_cmd - self.cmd_prev) / n
        vff0, d_vff = self.vff_prev, (self.vel_ff - self.vff_prev) / n
        t_ff = self.p.kaff * self.p.torque_per_acceleration * (self.vel_ff - self.vff_prev) / dt
        ideal = self.ideal
        q = self.quantum
        p_meas = self.p_last
        limited = False
        for i in range(n):
            pos_cmd = cmd0 + d_cmd * (i + 1)
            vel_ff = vff0 + d_vff * (i + 1)
            p_prev = p_meas
            p_meas = pos if ideal else round(pos / q) * q
            if enabled:
                v_meas = vel if ideal else (p_meas - p_prev) / h
                v_cmd = kv * (pos_cmd - p_meas) + kff * vel_ff
                speed_limited = not ideal and abs(v_cmd) > v_max
                if speed_limited:
                    v_cmd = math.copysign(v_max, v_cmd)
                e = v_cmd - v_meas
                t_cmd = kp * e + ki * xi + t_ff
                torque_limited = not ideal and abs(t_cmd) > t_max
                if torque_limited:
                    t_cmd = math.copysign(t_max, t_cmd)
                if speed_limited or torque_limited:
                    # Conditional integration: no windup while a limit acts, so the speed runs into
                    # its limit on the (over-damped) P loop and does not overshoot it.
                    limited = True
                else:
                    xi += e * h
            else:
                t_cmd, xi = 0.0, 0.0
            # Coulomb friction: sliding opposes the speed; at rest it balances up to tau_coulomb.
            if ideal or tc == 0.0:
                t_fr = 0.0
            elif vel != 0.0:
                t_fr = math.copysign(tc, vel)
            else:
                t_fr = min(max(torque, -tc), tc)
            torque, pos_n, vel_n = (a00 * torque + a01 * pos + a02 * vel + b00 * t_cmd + b01 * t_fr,
                                    a10 * torque + a11 * pos + a12 * vel + b10 * t_cmd + b11 * t_fr,
                                    a20 * torque + a21 * pos + a22 * vel + b20 * t_cmd + b21 * t_fr)
            if t_fr != 0.0:
                if vel == 0.0 and abs(torque) <= tc:
                    pos_n, vel_n = pos, 0.0          # stick
                elif vel * vel_n < 0.0:
                    # Sliding friction stopped the axis within the sub-step (re-decided next sub-step).
                    # Friction only brakes: the axis stops where a uniform deceleration from vel to 0
                    # takes it, never behind where it was, however large tau_coulomb is.
                    s_stop = vel / (vel - vel_n)     # fraction of the sub-step until the stop
                    pos_n, vel_n = pos + 0.5 * vel * s_stop * h, 0.0
            pos, vel = pos_n, vel_n
        self.x = np.array([xi, torque, pos, vel])
        self.p_last = p_meas          # the last sample the velocity loop took
        self.p_meas = pos if ideal else round(pos / q) * q
        self.limited = limited

    def _publish(self, pos: float, vel: float, torque: float) -> dict[str, object]:
        out = self._outputs
        fe = self.pos_cmd - pos
        out["pos"] = pos
        out["vel"] = vel
        out["following_error"] = fe
        out["in_position"] = abs(fe) <= self.inpos_band
        out["torque"] = float(torque)
        out["limited"] = self.limited
        return out
