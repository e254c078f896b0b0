"""The master loop in C (``loop.c``): the same steps as
:meth:`Execution.steps <ncfmu.cosim.execution.Execution.steps>`, outside Python, in the order of the algorithm's
schedule (:meth:`ncfmu.cosim.algorithm.Algorithm.schedule`, handed to the loop as an array).

Used when every slave offers its raw FMI 2.0 functions (:class:`NativeSlave`, i.e. every
:class:`~ncfmu.cosim.fmu.FmuSlave`) and the library could be built; otherwise the master runs its
Python loop. The library is compiled once with the system C compiler into ``build/`` of the project
root (a checkout, or the per-version user cache of a wheel install) by ``ncfmu build``, or on first use,
named by the digest of its source.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import shutil
import subprocess
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from ..errors import SimulationError
from ..files import project_root
from .algorithm import READ, Schedule
from .slave import KINDS, Slave

SOURCE = Path(__file__).with_name("loop.c")
#: -ffp-contract=off: no fused multiply-add, so a step's time is computed exactly as the Python loop does
FLAGS = ("-shared", "-fPIC", "-O2", "-ffp-contract=off")

#: The calls a failure report names (loop.c's CALL_SET, CALL_DO_STEP, CALL_GET).
CALLS = ("Set", "DoStep", "Get")


@dataclass(frozen=True)
class Fmi2Functions:
    """One FMU instance's component and the addresses of the FMI 2.0 functions the loop calls."""

    component: int
    do_step: int
    set: dict[str, int]       # kind -> fmi2SetReal / fmi2SetInteger / fmi2SetBoolean
    get: dict[str, int]       # kind -> fmi2GetXxx


@runtime_checkable
class NativeSlave(Slave, Protocol):
    """A slave the C loop can drive directly."""

    def fmi2_functions(self) -> Fmi2Functions:
        """The raw functions; the caller sets inputs behind the slave's back from now on."""
        ...

    def fmi2_failure(self, what: str, status: int) -> SimulationError:
        """The error the slave's own loop calls raise for ``what`` returning ``status``."""
        ...

    def forget_sent_inputs(self) -> None:
        """The C loop set the inputs: the slave's next ``write_inputs`` (Python calls again) sends every one."""
        ...


class _Transfer(ctypes.Structure):
    _fields_ = [("function", ctypes.c_void_p), ("vrs", ctypes.c_void_p), ("n", ctypes.c_size_t),
                ("data", ctypes.c_void_p), ("gather", ctypes.c_void_p), ("vector", ctypes.c_void_p),
                ("sent", ctypes.c_void_p), ("sent_valid", ctypes.c_void_p), ("is_real", ctypes.c_int32),
                ("kind", ctypes.c_int32)]


class _Slave(ctypes.Structure):
    _fields_ = [("component", ctypes.c_void_p), ("do_step", ctypes.c_void_p), ("writes", ctypes.POINTER(_Transfer)),
                ("reads", ctypes.POINTER(_Transfer)), ("n_writes", ctypes.c_int32), ("n_reads", ctypes.c_int32)]


class _Record(ctypes.Structure):
    _fields_ = [("table", ctypes.c_void_p), ("vector", ctypes.c_void_p), ("bytes", ctypes.c_size_t)]


class _Failure(ctypes.Structure):
    _fields_ = [("status", ctypes.c_int32), ("slave", ctypes.c_int32), ("call", ctypes.c_int32),
                ("kind", ctypes.c_int32), ("step", ctypes.c_int64)]


def library_path(root: Path) -> Path:
    digest = hashlib.sha256(SOURCE.read_bytes() + " ".join(FLAGS).encode()).hexdigest()[:12]
    return root / "build" / f"ncfmu_loop-{digest}.so"


def build_library(root: Path) -> Path | None:
    """Compile the loop into ``root/build`` unless it is there; its path, or None (with a warning)."""
    target = library_path(root)
    if target.is_file():
        return target
    cc = next((c for c in ("cc", "gcc", "clang") if shutil.which(c)), None)
    if cc is None:
        warnings.warn("ncfmu: no C compiler found; the master runs its Python loop", stacklevel=2)
        return None
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        # compiled next to the target and renamed: concurrent workers never load a half-written file
        fd, partial = tempfile.mkstemp(prefix=target.name, suffix=".part", dir=target.parent)
    except OSError as err:
        warnings.warn(f"ncfmu: cannot build the master loop in {target.parent} ({err}); the master runs its "
                      "Python loop", stacklevel=2)
        return None
    os.close(fd)
    try:
        proc = subprocess.run([cc, *FLAGS, "-o", partial, str(SOURCE)], capture_output=True, text=True)
        if proc.returncode != 0:
            warnings.warn(f"ncfmu: compiling the master loop failed ({proc.stderr.strip()[:300]}); "
                          "the master runs its Python loop", stacklevel=2)
            return None
        os.replace(partial, target)
    finally:
        if os.path.exists(partial):
            os.unlink(partial)
    return target


@functools.lru_cache(maxsize=1)
def library() -> ctypes.CDLL | None:
    """The compiled loop of the project root (built by ``ncfmu build``, or here on first use), or None."""
    path = build_library(project_root())
    if path is None:
        return None
    try:
        # CDLL: the loop runs without the GIL; the Python FMUs take it themselves in every call
        lib = ctypes.CDLL(str(path))
    except OSError as err:
        warnings.warn(f"ncfmu: cannot load the master loop ({err}); the master runs its Python loop", stacklevel=2)
        return None
    fn = lib.ncfmu_loop
    fn.restype = ctypes.c_int
    fn.argtypes = [ctypes.POINTER(_Slave), ctypes.c_void_p, ctypes.c_int32, ctypes.c_double, ctypes.c_double,
                   ctypes.c_int64, ctypes.c_int64, ctypes.POINTER(_Record), ctypes.c_int32, ctypes.c_int64,
                   ctypes.c_int64, ctypes.POINTER(_Failure)]
    return lib


class NativePlan:
    """One run's loop plan for the C loop: built from the master's bindings, kept alive with its arrays."""

    def __init__(self, slaves: list[NativeSlave], bindings: list[dict[str, tuple]], values: dict[str, np.ndarray],
                 records: list[tuple[np.ndarray, np.ndarray]], start: float, h: float, schedule: Schedule,
                 every: int = 1) -> None:
        """``bindings[i][kind]`` = ``(in_buf, input_vrs, gather_idx, out_view, output_vrs)`` of slave ``i``;
        ``gather_idx`` is used as it is (the master changes it in place between calls: forced inputs),
        ``records`` are (window table, vector) pairs: row r of the run goes to row r - row_base of the table."""
        lib = library()
        assert lib is not None
        self._loop = lib.ncfmu_loop
        self.slaves = slaves
        self._keep: list[object] = []        # every array the structures point into
        self._sent_valid: list[np.ndarray] = []
        self._structs = (_Slave * len(slaves))()
        for i, (s, bound) in enumerate(zip(slaves, bindings)):
            f = s.fmi2_functions()
            writes, reads = [], []
            for k, kind in enumerate(KINDS):
                if kind not in bound:
                    continue
                in_buf, in_vrs, idx, out_view, out_vrs = bound[kind]
                real = kind == "Real"
                if len(in_vrs):
                    vrs = np.asarray(in_vrs, dtype=np.uintc)
                    gather = idx
                    assert gather.dtype == np.intp and gather.flags.c_contiguous
                    sent = np.zeros_like(in_buf)
                    valid = np.zeros(1, dtype=np.int32)
                    self._keep += [vrs, gather, sent, in_buf, values[kind]]
                    self._sent_valid.append(valid)
                    writes.append(_Transfer(f.set[kind], vrs.ctypes.data, len(vrs), in_buf.ctypes.data,
                                            gather.ctypes.data, values[kind].ctypes.data, sent.ctypes.data,
                                            valid.ctypes.data, real, k))
                if len(out_vrs):
                    vrs = np.asarray(out_vrs, dtype=np.uintc)
                    self._keep += [vrs, out_view]
                    reads.append(_Transfer(f.get[kind], vrs.ctypes.data, len(vrs), out_view.ctypes.data,
                                           None, None, None, None, real, k))
            w, r = (_Transfer * len(writes))(*writes), (_Transfer * len(reads))(*reads)
            self._keep += [w, r]
            self._structs[i] = _Slave(f.component, f.do_step, ctypes.cast(w, ctypes.POINTER(_Transfer)),
                                      ctypes.cast(r, ctypes.POINTER(_Transfer)), len(writes), len(reads))
        self._records = (_Record * len(records))(*[_Record(table.ctypes.data, vector.ctypes.data,
                                                           vector.nbytes) for table, vector in records])
        for table, vector in records:
            assert table.flags.c_contiguous and vector.flags.c_contiguous and table.shape[1:] == vector.shape
        self._keep += [records]
        # the algorithm's schedule, as loop.c reads it: (what, slave) pairs of int32
        self._schedule = np.ascontiguousarray(schedule, dtype=np.int32).reshape(-1, 2)
        assert not self._schedule.size or (self._schedule[:, 1].max() < len(slaves)
                                           and self._schedule.min() >= 0 and self._schedule[:, 0].max() <= READ), \
            "the schedule names only this plan's slaves and the calls GATHER, STEP, READ"
        self.start, self.h, self.every = start, h, every
        self._failure = _Failure()

    def forget_sent(self) -> None:
        """Send every input at the next step (the FMUs' inputs may have changed: start values, a restored state)."""
        for valid in self._sent_valid:
            valid[0] = 0

    def run(self, first: int, last: int, row_base: int = 0) -> None:
        """Steps ``first`` .. ``last - 1``, recording into the window whose row 0 is the run's row ``row_base``;
        a failing FMI call raises the slave's SimulationError (:attr:`failed_step` is its step)."""
        status = self._loop(self._structs, self._schedule.ctypes.data, len(self._schedule), self.start, self.h,
                            first, last, self._records, len(self._records), self.every, row_base,
                            ctypes.byref(self._failure))
        if status:
            f = self._failure
            self.failed_step = int(f.step)
            slave = self.slaves[f.slave]
            call = CALLS[f.call]
            if call == "DoStep":
                what = f"fmi2DoStep at t = {self.start + self.h * f.step:.6f} s"
            else:
                what = f"fmi2{call}{KINDS[f.kind]}"
            raise slave.fmi2_failure(what, status)
