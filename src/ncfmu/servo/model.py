"""python-control models of a feed axis: position loop, PI velocity loop, current loop, mechanics.

Factories return named :class:`control.StateSpace` systems whose signals connect by name; the
closed loop is :func:`servo_axis`. Units: position mm, velocity mm/s, torque N·m.

Signal flow::

    pos_cmd, vel_ff, acc_ff --> position_controller --vel_cmd--> velocity_controller --torque_cmd-->
        current_loop --torque--> mechanics --pos, vel--> (back to both controllers)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import control as ct
import numpy as np

from .parameters import AxisParameters  # noqa: F401  (the parameters of every factory below)


def _static(d, inputs, outputs, name):
    d = np.atleast_2d(np.asarray(d, dtype=float))
    return ct.ss(np.zeros((0, 0)), np.zeros((0, d.shape[1])), np.zeros((d.shape[0], 0)), d,
                 inputs=inputs, outputs=outputs, name=name)


def position_controller(Kv: float, kff: float, name: str = "position_controller") -> ct.StateSpace:
    """Proportional position loop with velocity feed-forward.

    ``vel_cmd = Kv * (pos_cmd - pos) + kff * vel_ff``
    """
    return _static([[Kv, kff, -Kv]], ["pos_cmd", "vel_ff", "pos"], ["vel_cmd"], name)


def velocity_controller(Kp: float, Ki: float, Ka: float = 0.0, name: str = "velocity_controller") -> ct.StateSpace:
    """PI velocity loop with torque feed-forward; its state is the integral of the velocity error (mm).

    ``torque_cmd = Kp * (vel_cmd - vel) + Ki * ∫(vel_cmd - vel) dt + Ka * acc_ff``
    """
    return ct.ss([[0.0]], [[1.0, -1.0, 0.0]], [[Ki]], [[Kp, -Kp, Ka]], inputs=["vel_cmd", "vel", "acc_ff"],
                 outputs=["torque_cmd"], states=["integral"], name=name)


def current_loop(tau_current: float, name: str = "current_loop") -> ct.StateSpace:
    """Closed current loop as a first-order lag from commanded to motor torque."""
    return ct.ss([[-1.0 / tau_current]], [[1.0 / tau_current]], [[1.0]], [[0.0]],
                 inputs=["torque_cmd"], outputs=["torque"], states=["torque"], name=name)


def mechanics(J: float, pitch: float, b_visc: float, friction_input: bool = False,
              name: str = "mechanics") -> ct.StateSpace:
    """Motor + ball screw + load: torque (N·m) in, position (mm) and velocity (mm/s) out.

    ``J * dω/dt = torque - torque_friction - b_visc * ω`` with ``ω = 2π/pitch * vel``; the
    Coulomb friction torque is a second input when ``friction_input`` is true.
    """
    k = 2.0 * math.pi / pitch
    A = [[0.0, 1.0], [0.0, -b_visc / J]]
    B = [[0.0, 0.0], [1.0 / (J * k), -1.0 / (J * k)]]
    inputs = ["torque", "torque_friction"]
    if not friction_input:
        B, inputs = [row[:1] for row in B], inputs[:1]
    return ct.ss(A, B, np.eye(2), np.zeros((2, len(inputs))), inputs=inputs,
                 outputs=["pos", "vel"], states=["pos", "vel"], name=name)


def servo_axis(p: AxisParameters = AxisParameters(), name: str = "servo_axis") -> ct.StateSpace:
    """The linear closed loop of one axis.

    Parameters
    ----------
    p : AxisParameters

    Returns
    -------
    control.StateSpace
        Inputs ``pos_cmd, vel_ff, acc_ff`` (mm, mm/s, mm/s²); outputs ``pos, vel, following_error, torque``; states
        ``integral, torque, pos, vel`` (in that order).
    """
    kp, ki = p.velocity_gains
    error = ct.summing_junction(inputs=["pos_cmd", "-pos"], output="following_error", name="error")
    sys = ct.interconnect(
        [velocity_controller(kp, ki, p.kaff * p.torque_per_acceleration), current_loop(p.tau_current),
         mechanics(p.J, p.pitch, p.b_visc), position_controller(p.Kv, p.kff), error],
        inputs=["pos_cmd", "vel_ff", "acc_ff"], outputs=["pos", "vel", "following_error", "torque"], name=name)
    # interconnect stacks the subsystems' states in list order; name them plainly.
    assert [s.split("_", 2)[-1] for s in sys.state_labels] == ["integral", "torque", "pos", "vel"], sys.state_labels
    return ct.ss(sys.A, sys.B, sys.C, sys.D, inputs=sys.input_labels, outputs=sys.output_labels,
                 states=["integral", "torque", "pos", "vel"], name=name)


def drive_plant(p: AxisParameters = AxisParameters(), name: str = "drive_plant") -> ct.StateSpace:
    """Current loop + mechanics: what a digital drive controls.

    Inputs ``torque_cmd, torque_friction``; states and outputs ``torque, pos, vel``.
    """
    sys = ct.interconnect([current_loop(p.tau_current), mechanics(p.J, p.pitch, p.b_visc, friction_input=True)],
                          inputs=["torque_cmd", "torque_friction"], outputs=["torque", "pos", "vel"], name=name)
    return ct.ss(sys.A, sys.B, sys.C, sys.D, inputs=sys.input_labels, outputs=sys.output_labels,
                 states=["torque", "pos", "vel"], name=name)


def discretize(sys: ct.StateSpace, h: float) -> ct.StateSpace:
    """Exact zero-order-hold discretisation at step ``h`` (s)."""
    return ct.c2d(sys, h, method="zoh")


# -- design: the loops opened, their margins and bandwidths ------------------------------------
#: The smallest phase margin ncfmu accepts for either loop, degrees.
MIN_PHASE_MARGIN = 30.0


def velocity_loop(p: AxisParameters = AxisParameters(), name: str = "velocity_loop") -> ct.TransferFunction:
    """The velocity loop opened at the velocity feedback: velocity error (mm/s) in, velocity (mm/s) out.

    PI controller, current loop and mechanics in series (the feed-forwards do not change the loop).
    A transfer function, reduced: the mechanics' position state is not seen from the velocity.
    """
    kp, ki = p.velocity_gains
    pi = velocity_controller(kp, ki)[0, 0]                        # vel_cmd -> torque_cmd
    mech = mechanics(p.J, p.pitch, p.b_visc)[1, 0]                # torque -> vel
    loop = ct.minreal(ct.tf(ct.series(pi, current_loop(p.tau_current), mech)), verbose=False)
    return ct.tf(loop.num, loop.den, name=name, inputs="vel_error", outputs="vel")


def position_loop(p: AxisParameters = AxisParameters(), name: str = "position_loop") -> ct.TransferFunction:
    """The position loop opened at the position feedback: position error (mm) in, position (mm) out.

    ``Kv`` times the closed velocity loop times an integrator (position is the integral of velocity).
    """
    closed = ct.feedback(velocity_loop(p), 1)
    loop = ct.minreal(p.Kv * closed * ct.tf([1.0], [1.0, 0.0]), verbose=False)
    return ct.tf(loop.num, loop.den, name=name, inputs="pos_error", outputs="pos")


@dataclass(frozen=True)
class LoopDesign:
    """Design figures of one axis (continuous model; the drive's sampling is bounded separately).

    Phase margins in degrees (as :func:`control.margin` gives them), crossovers and closed-loop -3 dB
    bandwidths in rad/s.
    """

    velocity_margin: float
    velocity_crossover: float
    velocity_bandwidth: float
    position_margin: float
    position_crossover: float
    position_bandwidth: float
    stable: bool

    def refusal(self, p: AxisParameters) -> tuple[str, float, str] | None:
        """``(parameter, value, rule)`` when the design is unstable or lacks phase margin, else None.

        The velocity loop is shaped by ``vel_bandwidth`` (against the current loop's lag); the position
        loop by ``Kv`` (against the velocity loop's bandwidth): the parameter named is the one to change.
        """
        if not (self.velocity_margin >= MIN_PHASE_MARGIN):
            return ("vel_bandwidth", p.vel_bandwidth,
                    f"gives the velocity loop a phase margin of {self.velocity_margin:.1f} deg (< "
                    f"{MIN_PHASE_MARGIN:g} deg) with tau_current = {p.tau_current:g} s; lower vel_bandwidth")
        if not (self.position_margin >= MIN_PHASE_MARGIN):
            return ("Kv", p.Kv,
                    f"gives the position loop a phase margin of {self.position_margin:.1f} deg (< "
                    f"{MIN_PHASE_MARGIN:g} deg) with vel_bandwidth = {p.vel_bandwidth:g} rad/s; lower Kv")
        if not self.stable:
            return ("Kv", p.Kv, "the closed loop is unstable; lower Kv or vel_bandwidth")
        return None


def design(p: AxisParameters = AxisParameters()) -> LoopDesign:
    """Margins and bandwidths of both loops of the axis ``p`` (python-control)."""
    lv, lp = velocity_loop(p), position_loop(p)
    _, pm_v, _, wc_v = ct.margin(lv)
    _, pm_p, _, wc_p = ct.margin(lp)
    stable = bool(np.all(np.real(ct.poles(servo_axis(p))) < 0))
    return LoopDesign(float(pm_v), float(wc_v), _bandwidth(ct.feedback(lv, 1)),
                      float(pm_p), float(wc_p), _bandwidth(ct.feedback(lp, 1)), stable)


def _bandwidth(closed) -> float:
    """The -3 dB bandwidth, or NaN where python-control's search finds no bracket (a loop whose mechanics are
    far faster than its control, e.g. J/b_visc of nanoseconds): a design figure only, the checks use margins."""
    try:
        return float(ct.bandwidth(closed))
    except ValueError:
        return float("nan")
