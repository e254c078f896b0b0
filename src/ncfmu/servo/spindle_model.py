"""python-control models of a lathe spindle drive: PI speed loop, current loop, spindle mechanics.

Factories return named :class:`control.StateSpace` systems whose signals connect by name; the closed
loop is :func:`spindle_drive`, the loop opened for the design :func:`speed_loop`, its figures
:func:`design`. Units: speed rad/s, angle rad, torque N·m (the FMU's ports are in rev/min; the
conversion is :data:`~ncfmu.servo.parameters.RAD_S_PER_RPM`).

Signal flow::

    speed_cmd --> speed_controller --torque_cmd--> current_loop --torque--> spindle_mechanics --speed-->
                  (back to the speed controller)

The current loop is the feed axis's (:func:`ncfmu.servo.model.current_loop`); the speed loop is shaped
as the feed axis's velocity loop, by its crossover (``speed_bandwidth``) with the PI zero a quarter of
it below, so both drives are designed and refused by the same phase-margin rule.
"""

from __future__ import annotations

from dataclasses import dataclass

import control as ct
import numpy as np

from .model import MIN_PHASE_MARGIN, current_loop, discretize
from .parameters import SpindleParameters

__all__ = ["MIN_PHASE_MARGIN", "SpindleDesign", "SpindleParameters", "design", "discretize", "speed_controller",
           "speed_loop", "spindle_drive", "spindle_mechanics", "spindle_plant"]


def speed_controller(Kp: float, Ki: float, name: str = "speed_controller") -> ct.StateSpace:
    """PI speed controller; its state is the integral of the speed error (rad).

    ``torque_cmd = Kp * (speed_cmd - speed) + Ki * ∫(speed_cmd - speed) dt``

    Parameters
    ----------
    Kp : float
        Proportional gain, N·m/(rad/s).
    Ki : float
        Integral gain, N·m/rad.
    name : str
        Name of the system.

    Returns
    -------
    control.StateSpace
        Inputs ``speed_cmd, speed`` (rad/s); output ``torque_cmd`` (N·m); state ``integral``.
    """
    return ct.ss([[0.0]], [[1.0, -1.0]], [[Ki]], [[Kp, -Kp]], inputs=["speed_cmd", "speed"],
                 outputs=["torque_cmd"], states=["integral"], name=name)


def spindle_mechanics(J: float, b_visc: float, friction_input: bool = False,
                      name: str = "spindle_mechanics") -> ct.StateSpace:
    """Motor + spindle + chuck + workpiece: torque in, angle and speed out.

    ``J * dω/dt = torque - torque_friction - b_visc * ω``; the Coulomb friction torque is a second
    input when ``friction_input`` is true.

    Parameters
    ----------
    J : float
        Inertia, kg·m².
    b_visc : float
        Viscous friction, N·m·s/rad.
    friction_input : bool
        Add the input ``torque_friction`` (N·m, opposing positive rotation).
    name : str
        Name of the system.

    Returns
    -------
    control.StateSpace
        Inputs ``torque`` (and ``torque_friction``); outputs and states ``angle`` (rad), ``speed`` (rad/s).
    """
    A = [[0.0, 1.0], [0.0, -b_visc / J]]
    B = [[0.0, 0.0], [1.0 / J, -1.0 / J]]
    inputs = ["torque", "torque_friction"]
    if not friction_input:
        B, inputs = [row[:1] for row in B], inputs[:1]
    return ct.ss(A, B, np.eye(2), np.zeros((2, len(inputs))), inputs=inputs,
                 outputs=["angle", "speed"], states=["angle", "speed"], name=name)


def _renamed(sys: ct.StateSpace, states: list[str], name: str) -> ct.StateSpace:
    """``sys`` with its states named plainly (interconnect prefixes them with the subsystem's name)."""
    assert [s.split("_", 2)[-1] for s in sys.state_labels] == states, sys.state_labels
    return ct.ss(sys.A, sys.B, sys.C, sys.D, inputs=sys.input_labels, outputs=sys.output_labels,
                 states=states, name=name)


def spindle_drive(p: SpindleParameters = SpindleParameters(), load_input: bool = False,
                  name: str = "spindle_drive") -> ct.StateSpace:
    """The linear closed speed loop of the spindle (no limits, no Coulomb friction).

    Parameters
    ----------
    p : SpindleParameters
    load_input : bool
        Add the input ``torque_load`` (N·m, opposing positive rotation): the loop's answer to a cutting torque.
    name : str
        Name of the system.

    Returns
    -------
    control.StateSpace
        Input ``speed_cmd`` (rad/s) (and ``torque_load``); outputs ``speed`` (rad/s), ``torque`` (N·m); states
        ``integral, torque, angle, speed`` (in that order). The angle is the speed's integral: its pole at 0 is
        not the loop's.
    """
    kp, ki = p.speed_gains
    sys = ct.interconnect(
        [speed_controller(kp, ki), current_loop(p.tau_current),
         spindle_mechanics(p.J, p.b_visc, friction_input=load_input)],
        inputs=["speed_cmd", "torque_friction"] if load_input else ["speed_cmd"], outputs=["speed", "torque"],
        ignore_outputs=["angle"], name=name)
    sys = _renamed(sys, ["integral", "torque", "angle", "speed"], name)
    if load_input:
        sys = ct.ss(sys.A, sys.B, sys.C, sys.D, inputs=["speed_cmd", "torque_load"], outputs=sys.output_labels,
                    states=sys.state_labels, name=name)
    return sys


def spindle_plant(p: SpindleParameters = SpindleParameters(), name: str = "spindle_plant") -> ct.StateSpace:
    """Current loop + mechanics: what the digital speed controller drives.

    Returns
    -------
    control.StateSpace
        Inputs ``torque_cmd, torque_friction`` (N·m); states and outputs ``torque, angle, speed``.
    """
    sys = ct.interconnect([current_loop(p.tau_current), spindle_mechanics(p.J, p.b_visc, friction_input=True)],
                          inputs=["torque_cmd", "torque_friction"], outputs=["torque", "angle", "speed"],
                          name=name)
    return _renamed(sys, ["torque", "angle", "speed"], name)


# -- design: the speed loop opened, its margins and bandwidth -------------------------------------
def speed_loop(p: SpindleParameters = SpindleParameters(), name: str = "speed_loop") -> ct.TransferFunction:
    """The speed loop opened at the speed feedback: speed error (rad/s) in, speed (rad/s) out.

    PI controller, current loop and mechanics in series, as a reduced transfer function.
    """
    kp, ki = p.speed_gains
    pi = speed_controller(kp, ki)[0, 0]                          # speed_cmd -> torque_cmd
    mech = spindle_mechanics(p.J, p.b_visc)[1, 0]                 # torque -> speed
    loop = ct.minreal(ct.tf(ct.series(pi, current_loop(p.tau_current), mech)), verbose=False)
    return ct.tf(loop.num, loop.den, name=name, inputs="speed_error", outputs="speed")


@dataclass(frozen=True)
class SpindleDesign:
    """Design figures of the speed loop (continuous model; its sampling is bounded separately).

    Phase margin in degrees and gain margin as a factor (as :func:`control.margin` gives them, inf when the phase
    never reaches -180 deg); crossover and closed-loop -3 dB bandwidth in rad/s.
    """

    phase_margin: float
    gain_margin: float
    crossover: float
    bandwidth: float
    stable: bool

    def refusal(self, p: SpindleParameters) -> tuple[str, float, str] | None:
        """``(parameter, value, rule)`` when the loop is unstable or lacks phase margin, else None: the loop is
        shaped by ``speed_bandwidth`` (against the current loop's lag), the parameter to change."""
        if not (self.phase_margin >= MIN_PHASE_MARGIN):
            return ("speed_bandwidth", p.speed_bandwidth,
                    f"gives the speed loop a phase margin of {self.phase_margin:.1f} deg (< {MIN_PHASE_MARGIN:g} "
                    f"deg) with tau_current = {p.tau_current:g} s; lower speed_bandwidth")
        if not self.stable:
            return ("speed_bandwidth", p.speed_bandwidth, "the speed loop is unstable; lower speed_bandwidth")
        return None


def design(p: SpindleParameters = SpindleParameters()) -> SpindleDesign:
    """Margins and bandwidth of the speed loop of the spindle ``p`` (python-control).

    Stability is that of the closed speed loop (:func:`control.feedback` of :func:`speed_loop`): the closed
    drive's angle state is an integrator outside the loop.
    """
    loop = speed_loop(p)
    gm, pm, _, wc = ct.margin(loop)
    closed = ct.feedback(loop, 1)
    stable = bool(np.all(np.real(ct.poles(closed)) < 0))
    try:
        bandwidth = float(ct.bandwidth(closed))
    except ValueError:       # no -3 dB bracket found: a design figure only, the checks use the margin
        bandwidth = float("nan")
    return SpindleDesign(float(pm), float(gm), float(wc), bandwidth, stable)
