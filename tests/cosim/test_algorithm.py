"""The step order is said once, by the algorithm's schedule, and every loop follows it: the Python loop, the rest of a
step an FMU ended, and the C loop (cosim/loop.c), shown with fake slaves whose calls are logged."""

from __future__ import annotations

import ctypes
import re
from pathlib import Path

import numpy as np
import pytest

from ncfmu.cosim import algorithm as alg
from ncfmu.cosim.algorithm import GATHER, READ, STEP, GaussSeidel, Jacobi
from ncfmu.cosim.native_loop import Fmi2Functions, NativePlan, library

N = 3          # slaves in a ring: slave k's input is slave k - 1's output; each step makes y = u + 1


def test_the_schedules_say_the_two_orders():
    assert GaussSeidel().schedule(2) == ((GATHER, 0), (STEP, 0), (READ, 0), (GATHER, 1), (STEP, 1), (READ, 1))
    assert Jacobi().schedule(2) == ((GATHER, 0), (GATHER, 1), (STEP, 0), (STEP, 1), (READ, 0), (READ, 1))


def test_loop_c_numbers_the_calls_as_the_algorithm_does():
    source = (Path(alg.__file__).with_name("loop.c")).read_text()
    found = re.search(r"enum \{ PLAN_GATHER = (\d), PLAN_STEP = (\d), PLAN_READ = (\d) \}", source)
    assert found is not None and tuple(map(int, found.groups())) == (GATHER, STEP, READ)


class _Ring:
    """The value vector of the ring's outputs and, per slave, its input buffer and gather."""

    def __init__(self) -> None:
        self.values = np.zeros(N)
        self.inputs = [np.zeros(1) for _ in range(N)]
        self.gather = [np.array([(k - 1) % N], dtype=np.intp) for k in range(N)]


class _PySlave:
    def __init__(self, k: int, ring: _Ring, log: list) -> None:
        self.name, self.k, self.ring, self.log, self.y = f"s{k}", k, ring, log, 0.0

    def write_inputs(self) -> None:
        self.log.append(("set", self.k, float(self.ring.inputs[self.k][0])))

    def do_step(self, t: float, h: float) -> None:
        self.log.append(("step", self.k))
        self.y = float(self.ring.inputs[self.k][0]) + 1.0

    def read_outputs(self) -> None:
        self.log.append(("get", self.k))
        self.ring.values[self.k] = self.y


def _python_log(algorithm, steps: int) -> list:
    ring, log = _Ring(), []
    plan = [(_PySlave(k, ring, log), ((ring.inputs[k], ring.values.take, ring.gather[k]),)) for k in range(N)]
    step = algorithm.stepper(plan)
    for i in range(steps):
        step(i * 0.001, 0.001)
    return log


@pytest.mark.parametrize("algorithm", [GaussSeidel(), Jacobi()], ids=lambda a: a.name)
def test_the_python_loop_follows_the_schedule(algorithm):
    log = _python_log(algorithm, 2)
    if isinstance(algorithm, GaussSeidel):      # each slave sees the newest output: the ring climbs within a step
        assert log[:6] == [("set", 0, 0.0), ("step", 0), ("get", 0), ("set", 1, 1.0), ("step", 1), ("get", 1)]
        assert [e[2] for e in log if e[0] == "set"] == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
    else:                                       # every slave sees the previous communication point
        assert log[:6] == [("set", 0, 0.0), ("step", 0), ("set", 1, 0.0), ("step", 1), ("set", 2, 0.0), ("step", 2)]
        assert [e[2] for e in log if e[0] == "set"] == [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]


@pytest.mark.parametrize("algorithm, rest", [
    (GaussSeidel(), [("get", 1), ("set", 2, 0.0), ("step", 2), ("get", 2)]),
    (Jacobi(), [("set", 2, 0.0), ("step", 2), ("get", 0), ("get", 1), ("get", 2)]),
], ids=["gauss-seidel", "jacobi"])
def test_the_rest_of_a_step_an_fmu_ended_follows_the_schedule(algorithm, rest):
    """Slave 1 made its step whole and asked to end: the step is finished by the calls after its step."""
    ring, log = _Ring(), []
    plan = [(_PySlave(k, ring, log), ((ring.inputs[k], ring.values.take, ring.gather[k]),)) for k in range(N)]
    algorithm.rest_of_step(plan, 1)(0.0, 0.001)
    assert log == rest


# -- the C loop over fake FMI functions (ctypes callbacks) -----------------------------------------------------------
_SET = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t,
                        ctypes.POINTER(ctypes.c_double))
_GET = _SET
_DO_STEP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)


class _CSlave:
    """A slave whose FMI functions are Python callbacks the C loop calls; component k + 1 identifies it."""

    def __init__(self, k: int, log: list) -> None:
        self.name, self.k, self.log, self.u, self.y = f"s{k}", k, log, 0.0, 0.0

        def set_real(c, vrs, n, values):
            self.u = values[0]
            log.append(("set", self.k, float(values[0])))
            return 0

        def do_step(c, t, h, flag):
            log.append(("step", self.k))
            self.y = self.u + 1.0
            return 0

        def get_real(c, vrs, n, values):
            log.append(("get", self.k))
            values[0] = self.y
            return 0

        self._callbacks = (_SET(set_real), _DO_STEP(do_step), _GET(get_real))

    def fmi2_functions(self) -> Fmi2Functions:
        address = [ctypes.cast(f, ctypes.c_void_p).value or 0 for f in self._callbacks]
        return Fmi2Functions(self.k + 1, address[1], {"Real": address[0]}, {"Real": address[2]})


@pytest.mark.parametrize("algorithm", [GaussSeidel(), Jacobi()], ids=lambda a: a.name)
def test_the_c_loop_follows_the_same_schedule(algorithm):
    assert library() is not None, "the C loop must build on this machine"
    ring, log = _Ring(), []
    slaves = [_CSlave(k, log) for k in range(N)]
    bindings = [{"Real": (ring.inputs[k], [0], ring.gather[k], ring.values[k:k + 1], [1])} for k in range(N)]
    plan = NativePlan(slaves, bindings, {"Real": ring.values}, [], 0.0, 0.001,  # type: ignore[arg-type]
                      algorithm.schedule(N))
    plan.run(0, 2)
    assert log == _python_log(algorithm, 2)
