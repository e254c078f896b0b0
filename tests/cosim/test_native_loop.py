"""The master's steps in C (cosim/loop.c) are the Python loop's steps, bit for bit.

The same systems run through both loops (``Master(native=False)`` is the Python loop) and every recorded
value must be equal, not close: the C loop makes the same FMI calls in the same order with the same values.
"""

import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from ncfmu.cosim.master import InputTable, Master
from ncfmu.cosim.native_loop import library
from ncfmu.project import OpenSystem

ROOT = Path(__file__).resolve().parents[2]

# M words at times off the step grid, one exactly on it, two in one step
M_WORDS = InputTable(np.array([0.0, 0.2345, 0.9, 1.4999999, 1.5000001, 2.6]),
                     {"panel.m_active": np.array([0.0, 3.0, 0.0, 5.0, 6.0, 0.0])})
HOLD = {"panel.hold_at": 1.0, "panel.release_at": 1.7}


def run(archive, native, mode="gauss-seidel", **kwargs):
    with OpenSystem(archive, mode) as opened:
        opened.master.native = native
        return opened.run(**kwargs), opened.master.loop_used


def assert_identical(a, b):
    assert a.data.dtype == b.data.dtype and len(a.data) == len(b.data)
    for name in a.data.dtype.names:
        assert np.array_equal(a.data[name], b.data[name]), name


@pytest.mark.parametrize("system", ["lathe_taper", "mill_contour"])
@pytest.mark.parametrize("mode", ["gauss-seidel", "jacobi"])
def test_the_c_loop_records_exactly_what_the_python_loop_records(project, system, mode):
    assert library() is not None, "the C loop must build on this machine"
    archive = ROOT / "ssp" / f"{system}.ssp"
    kwargs = {"stop_time": 3.0, "inputs": M_WORDS, "start_values": HOLD}
    python, loop = run(archive, False, mode, **kwargs)
    assert loop == "python"
    native, loop = run(archive, True, mode, **kwargs)
    assert loop == "c"
    assert_identical(python, native)
    # the run did something: the M words reached the panel (MFIN answered), the hold was pressed
    assert python["panel.mfin"].any() and python["panel.feed_hold"].any()


def test_progress_and_deadline_chunks_change_nothing(project):
    """Python acts between chunks of C steps (progress, deadline, input changes): still the same steps."""
    import time
    archive = ROOT / "ssp" / "lathe_taper.ssp"
    seen: list[float] = []
    python, _ = run(archive, False, stop_time=1.0, inputs=M_WORDS)
    native, _ = run(archive, True, stop_time=1.0, inputs=M_WORDS, progress=seen.append,
                    deadline=time.perf_counter() + 3600.0)
    assert_identical(python, native)
    assert seen == [pytest.approx(k / 100) for k in range(1, 101)]


def test_branches_through_the_c_loop_match_the_python_loop(project):
    archive = ROOT / "ssp" / "grinder_feed.ssp"
    variants = [{"panel.emergency_at": 3.0}, {"panel.emergency_at": 4.5}]
    out = []
    for native in (False, True):
        with OpenSystem(archive) as opened:
            opened.master.native = native
            out.append(opened.master.run_branches(2.0, variants, stop_time=6.0))
            assert opened.master.loop_used == ("c" if native else "python")
    for a, b in zip(*out):
        assert_identical(a, b)
    assert not np.array_equal(out[1][0]["x_axis.pos"], out[1][1]["x_axis.pos"])


FAILING_STEP = textwrap.dedent("""
    import sys
    from ncfmu.errors import SimulationError
    from ncfmu.fmi.builder import vendored_package
    from ncfmu.project import OpenSystem

    native = sys.argv[1] == "c"
    with OpenSystem(sys.argv[2]) as opened:
        opened.master.native = native
        panel = sys.modules[f"{vendored_package(sys.argv[3])}.controllers.panel"].OperatorPanel   # the FMU's copy
        # the method the binary's DoStep calls (compiled, it calls ``step`` natively: a patched ``step`` is not seen)
        step = panel.step_then_count_messages

        def broken(self, t, dt, inputs):
            if t >= 0.25:
                raise ZeroDivisionError("deliberate defect")
            return step(self, t, dt, inputs)
        panel.step_then_count_messages = broken
        try:
            opened.run(stop_time=1.0)
        except SimulationError as err:
            print("SimulationError:", err)
        else:
            print("no error")
""")


def test_an_fmi2error_mid_run_is_the_same_simulation_error_through_the_c_loop(project, tmp_path):
    """Run in subprocesses: a defect must not take the test process with it."""
    script = tmp_path / "fail.py"
    script.write_text(FAILING_STEP)
    said = {}
    for loop in ("python", "c"):
        done = subprocess.run([sys.executable, str(script), loop, str(ROOT / "ssp" / "lathe_taper.ssp"),
                               str(ROOT / "fmus" / "OperatorPanel.fmu")], capture_output=True, text=True,
                              timeout=300)
        assert done.returncode == 0, done.stderr
        # the traceback names the process's own unpacking folder
        said[loop] = re.sub(r"ncfmu_fmus_\w+", "ncfmu_fmus_*", done.stdout.strip())
    assert said["c"] == said["python"]
    assert said["c"].startswith("SimulationError: panel: fmi2DoStep at t = 0.250000 s returned fmi2Error")
    assert "deliberate defect" in said["c"]


def test_fake_slaves_keep_the_python_loop():
    from fakes import chain
    m, log = chain("gauss-seidel")
    r = m.run()
    assert list(r["b.y"]) == [0, 11, 22, 33] and log == ["a", "b"] * 3
    assert m.loop_used == "python"


def test_a_run_longer_than_one_chunk_is_the_same_run(project, monkeypatch):
    """The C loop hands back to Python every NATIVE_CHUNK steps (so Ctrl-C is seen): the chunks join seamlessly."""
    import ncfmu.cosim.execution as execution
    monkeypatch.setattr(execution, "NATIVE_CHUNK", 997)           # 3000 steps: three whole chunks and a part
    archive = ROOT / "ssp" / "lathe_taper.ssp"
    python, _ = run(archive, False, stop_time=3.0, start_values=HOLD)
    native, loop = run(archive, True, stop_time=3.0, start_values=HOLD)
    assert loop == "c"
    assert_identical(python, native)


def test_without_a_compiler_or_with_a_broken_source_the_loop_is_not_built_and_says_why(tmp_path, monkeypatch):
    """No C compiler, or a source that does not compile: a warning saying the Python loop runs, no library file
    (half-written or not) left behind, and nothing raised: the master falls back to its Python loop."""
    import ncfmu.cosim.native_loop as native_loop
    monkeypatch.setenv("PATH", str(tmp_path / "nothing"))
    with pytest.warns(UserWarning, match="no C compiler found; the master runs its Python loop"):
        assert native_loop.build_library(tmp_path) is None
    monkeypatch.undo()
    broken = tmp_path / "loop.c"
    broken.write_text("int ncfmu_loop(void) { return }\n")
    monkeypatch.setattr(native_loop, "SOURCE", broken)
    with pytest.warns(UserWarning, match=r"(?s)compiling the master loop failed .*the master runs its Python loop"):
        assert native_loop.build_library(tmp_path) is None
    assert list((tmp_path / "build").iterdir()) == []


def _fake_native_chain(fail_call=None, fail_step=None):
    """The fake y = u + k chain of test_master, its FMI functions as ctypes callbacks the C loop calls; the
    ``fail_call`` ("SetReal", "GetReal" or "DoStep") of slave b returns fmi2Error at step ``fail_step``."""
    import ctypes

    from fakes import FakeSlave

    from ncfmu.cosim.native_loop import Fmi2Functions
    from ncfmu.cosim.slave import KINDS
    from ncfmu.cosim.ssp import Component, Connection, System
    from ncfmu.errors import SimulationError

    transfer = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t,
                                ctypes.c_void_p)
    step_fn = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)

    class FakeNative(FakeSlave):
        def fmi2_functions(self):
            self.steps, self.keep = 0, []

            def fails(call):
                return self.name == "b" and fail_call == call and self.steps == fail_step

            def set_real(c, vrs, n, values):
                if fails("SetReal"):
                    return 3
                self.u = ctypes.cast(values, ctypes.POINTER(ctypes.c_double))[0] if n else self.u
                return 0

            def get_real(c, vrs, n, values):
                if fails("GetReal"):
                    return 3
                ctypes.cast(values, ctypes.POINTER(ctypes.c_double))[0] = self.y
                return 0

            def do_step(c, t, h, no_set_prior):
                self.steps += 1
                if fails("DoStep"):
                    return 3
                self.y = self.u + self.k
                return 0

            none = transfer(lambda c, vrs, n, values: 0)
            self.keep = [transfer(set_real), transfer(get_real), step_fn(do_step), none]

            def address(fn):
                return ctypes.cast(fn, ctypes.c_void_p).value
            sets = {kind: address(self.keep[0] if kind == "Real" else none) for kind in KINDS}
            gets = {kind: address(self.keep[1] if kind == "Real" else none) for kind in KINDS}
            return Fmi2Functions(1, address(self.keep[2]), sets, gets)

        def fmi2_failure(self, what, status):
            return SimulationError(f"{self.name}: {what} returned {status}")

        def forget_sent_inputs(self):
            pass                    # the fake sends every input at each write_inputs anyway

    log: list[str] = []
    a, b = FakeNative("a", log), FakeNative("b", log)
    system = System("chain", [Component("a", "Fake"), Component("b", "Fake", {"k": 10.0})],
                    [Connection("a", "y", "b", "u"), Connection("b", "y", "a", "u")], stop_time=0.005)
    return Master(system, [a, b])


def test_the_c_loop_calls_the_functions_it_is_given_and_names_a_failing_one():
    """Through fake FMI functions (ctypes callbacks): the C loop computes the Python loop's chain, and a Set, a
    DoStep or a Get returning fmi2Error ends the run with the slave's own error for that call."""
    from ncfmu.errors import SimulationError
    m = _fake_native_chain()
    r = m.run()
    assert m.loop_used == "c"
    assert list(r["a.y"]) == [0, 1, 12, 23, 34, 45] and list(r["b.y"]) == [0, 11, 22, 33, 44, 55]
    for call, says in (("SetReal", "fmi2SetReal"), ("DoStep", "fmi2DoStep"), ("GetReal", "fmi2GetReal")):
        m = _fake_native_chain(call, 2)
        with pytest.raises(SimulationError) as err:
            m.run()
        assert str(err.value).startswith(f"b: {says}") and "returned 3" in str(err.value), str(err.value)
