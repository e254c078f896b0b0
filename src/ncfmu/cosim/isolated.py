"""A foreign FMU in a process of its own, behind the master's :class:`~ncfmu.cosim.slave.Slave` interface.

A plant model from another tool may crash (a null pointer, ``abort()``, ``exit()``): in the master's process that
ends the run without a word and loses the rows not yet written. So an FMU ncfmu did not build runs in a child
process (``python -m ncfmu.cosim.isolated``) that drives it through the very slave the master would use in process
(:class:`~ncfmu.cosim.fmu.FmuSlave`, :class:`~ncfmu.cosim.fmu3.Fmu3Slave`: the same calls, the same errors), as
FMPy's remoting does. :class:`IsolatedSlave` is its proxy in the master:

- one round trip a step: ``write_inputs`` keeps the inputs, ``do_step`` sends them with the step, and the child
  answers with the outputs it read right after the step (``read_outputs`` copies them, no round trip); every other
  call is a round trip of its own;
- two pipes carry the calls (the child's stdout stays the FMU's own); what crosses them is numbers, text and the
  raw bytes of the buffers -- never a pickle (the child runs someone else's code);
- before each FMI call the child writes the call's name into a page both processes map (:data:`MARK_SIZE` bytes),
  so when the child dies the proxy knows the call it died in; it raises :class:`~ncfmu.errors.FmuCrashed` naming
  the instance, that call, the simulated time and how the process ended (the signal, or its exit status). After
  that every call raises the same error, and ``terminate`` does nothing.

An error the FMU reports (fmi2Error, a refused value, an FMU asking to end the run) crosses the pipe as the
exception the in-process slave raises, with the same message. Our own FMUs stay in process (and in the C loop).
"""

from __future__ import annotations

import json
import mmap
import os
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, FmuCrashed, SimulationError, SystemDefinitionError, TerminationRequested
from .fmu import UnpackedFmu
from .slave import DTYPES, Variable

__all__ = ["IsolatedSlave", "IsolatedStatefulSlave", "isolated_slave"]

#: Bytes of the page the child names its current FMI call in (UTF-8, NUL-padded).
MARK_SIZE = 256
#: How long a child that closed its pipe is given to be reaped, and one asked to leave to leave, s.
REAP_TIMEOUT = 5.0

_STEP = struct.Struct("<dd")
#: Tags of the first byte of a frame: a step's inputs, a JSON call; an answer: a step's outputs, a JSON answer.
_CALL_STEP, _CALL_JSON, _ANSWER_OUTPUTS, _ANSWER_JSON = b"S", b"J", b"O", b"A"


class _Pipe:
    """One direction of a pipe, in frames (a length, then the bytes): a frame written in one ``write`` and most read
    in one ``read`` (multiprocessing's Connection reads a frame's length and its bytes in two)."""

    _LENGTH = struct.Struct("<I")

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.closed = False
        self._buffer = b""

    def send_bytes(self, data: bytes) -> None:
        view = memoryview(self._LENGTH.pack(len(data)) + data)
        while view:
            view = view[os.write(self.fd, view):]

    def recv_bytes(self) -> bytes:
        """The next frame; EOFError when the other end closed the pipe."""
        buffer = self._buffer
        while len(buffer) < 4 or len(buffer) < 4 + self._LENGTH.unpack_from(buffer)[0]:
            more = os.read(self.fd, 1 << 16)
            if not more:
                raise EOFError("the pipe was closed")
            buffer += more
        end = 4 + self._LENGTH.unpack_from(buffer)[0]
        self._buffer = buffer[end:]
        return buffer[4:end]

    def close(self, _close: Callable[[int], None] = os.close) -> None:
        # os.close bound at definition: a proxy's __del__ may close its pipes at interpreter exit, when this
        # module's globals (os) are already gone
        if not self.closed:
            self.closed = True
            _close(self.fd)


class _Repr:
    """A value the child could only describe: its repr, so a ConfigError's message reads as the child's did."""

    def __init__(self, text: str) -> None:
        self.text = text

    def __repr__(self) -> str:
        return self.text


def _plain(value: object) -> object:
    """``value`` as JSON carries it (numpy scalars as Python numbers); anything else by its repr."""
    if isinstance(value, np.generic):
        value = value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, (list, tuple)) and all(isinstance(x, int) for x in value):
        return list(value)              # value references
    return {"repr": repr(value)}


def _unplain(value: object) -> object:
    return _Repr(value["repr"]) if isinstance(value, dict) else value


def _error_to_json(err: BaseException, instance: str) -> dict[str, Any]:
    if isinstance(err, TerminationRequested):
        return {"class": "TerminationRequested", "instance": err.instance, "time": err.time, "detail": err.detail,
                "last_time": err.last_time}
    if isinstance(err, ConfigError):
        return {"class": "ConfigError", "variable": err.variable, "value": _plain(err.value), "rule": err.rule}
    if isinstance(err, SystemDefinitionError):
        return {"class": "SystemDefinitionError", "message": str(err)}
    if isinstance(err, SimulationError):
        return {"class": "SimulationError", "message": str(err)}
    return {"class": "SimulationError", "message": f"{instance}: {type(err).__name__} in the FMU's process: {err}"}


def _error_from_json(e: dict[str, Any]) -> Exception:
    kind = e.get("class")
    if kind == "TerminationRequested":
        return TerminationRequested(e["instance"], e["time"], e["detail"], e["last_time"])
    if kind == "ConfigError":
        return ConfigError(e["variable"], _unplain(e["value"]), e["rule"])
    if kind == "SystemDefinitionError":
        return SystemDefinitionError(e["message"])
    return SimulationError(e["message"])


def _how_it_ended(returncode: int | None) -> str:
    if returncode is None:
        return "its process stopped answering"
    if returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = f"signal {-returncode}"
        return f"its process was killed by {name}"
    return f"its process exited with status {returncode}"


class _RemoteState:
    """An FMU state saved in the child (fmi2GetFMUstate there): a handle the child knows it by."""

    def __init__(self, handle: int) -> None:
        self.handle = handle


# -- the master's side ---------------------------------------------------------------------------------------
class IsolatedSlave:
    """The proxy of one FMU instance run in a child process (see the module's docstring)."""

    def __init__(self, directory: Path, instance_name: str, variables: dict[str, Variable]) -> None:
        self.name = instance_name
        self.variables = variables
        self.messages: list[tuple[str, str]] = []
        self.time = 0.0                 # the FMU's simulated time, for the message if it dies
        self._crashed: FmuCrashed | None = None
        self._inputs: list[np.ndarray] = []
        self._outputs: list[tuple[np.ndarray, np.dtype, int]] = []
        self._pending: bytes | None = None      # inputs kept by write_inputs, sent with the next call
        self._fresh: bytes | None = None        # the outputs the child read right after the last step
        self._workdir = Path(tempfile.mkdtemp(prefix="ncfmu_isolated_"))
        mark = tempfile.TemporaryFile(dir=self._workdir)
        mark.truncate(MARK_SIZE)
        self._mark = mmap.mmap(mark.fileno(), MARK_SIZE)
        calls_r, calls_w = os.pipe()
        answers_r, answers_w = os.pipe()
        try:
            self._process = subprocess.Popen(
                [sys.executable, "-m", "ncfmu.cosim.isolated", str(calls_r), str(answers_w), str(mark.fileno()),
                 str(directory), instance_name],
                pass_fds=(calls_r, answers_w, mark.fileno()), stdin=subprocess.DEVNULL)
        except OSError:
            for fd in (calls_r, calls_w, answers_r, answers_w):
                os.close(fd)
            mark.close()
            shutil.rmtree(self._workdir, ignore_errors=True)
            raise
        finally:
            mark.close()
        os.close(calls_r)
        os.close(answers_w)
        self._calls = _Pipe(calls_w)
        self._answers = _Pipe(answers_r)
        try:
            self._call("fmi2Instantiate", "instantiate")
        except BaseException:
            self.terminate()
            raise

    # -- the pipe ---------------------------------------------------------------------------------
    def _died(self, what: str, after_step: float | None = None) -> FmuCrashed:
        """The error of the child's death in ``what`` (the child's own mark names the FMI call when it got there);
        ``after_step``: the end of the step being made (the time of a crash in reading its outputs)."""
        try:
            returncode = self._process.wait(REAP_TIMEOUT)
        except subprocess.TimeoutExpired:
            self._process.kill()
            returncode = None
        called = bytes(self._mark[:]).rstrip(b"\0").decode("utf-8", "replace") or what
        time = self.time
        if after_step is not None and "Get" in called:
            time = after_step               # the step was made: its outputs were being read
        self._crashed = FmuCrashed(self.name, called, time, _how_it_ended(returncode))
        self._close_pipes()
        return self._crashed

    def _exchange(self, frame: bytes, what: str, after_step: float | None = None) -> bytes:
        if self._crashed is not None:
            raise self._crashed
        try:
            self._calls.send_bytes(frame)
            return self._answers.recv_bytes()
        except (EOFError, OSError):
            raise self._died(what, after_step) from None

    def _answer(self, answer: bytes, what: str) -> Any:
        """The value of a JSON answer, or the exception it carries (messages taken either way)."""
        body = json.loads(answer[1:])
        self.messages.extend((level, text) for level, text in body.get("messages", ()))
        if body.get("outputs"):
            try:
                self._fresh = self._answers.recv_bytes()
            except (EOFError, OSError):
                raise self._died(what) from None
        if "error" in body:
            raise _error_from_json(body["error"])
        if body.get("binary"):
            try:
                return self._answers.recv_bytes()
            except (EOFError, OSError):
                raise self._died(what) from None
        return body.get("value")

    def _call(self, what: str, op: str, *args: object, data: bytes | None = None) -> Any:
        """One call in the child (the inputs kept by write_inputs go first, in the same frame)."""
        self._fresh = None
        call = {"op": op, "args": [_plain(a) for a in args], "inputs": self._pending is not None,
                "data": data is not None}
        frame = _CALL_JSON + json.dumps(call).encode()
        if self._crashed is not None:
            raise self._crashed
        try:
            self._calls.send_bytes(frame)
            if self._pending is not None:
                self._calls.send_bytes(self._pending)
            if data is not None:
                self._calls.send_bytes(data)
        except OSError:
            raise self._died(what) from None
        self._pending = None
        try:
            answer = self._answers.recv_bytes()
        except (EOFError, OSError):
            raise self._died(what) from None
        return self._answer(answer, what)

    # -- set-up -----------------------------------------------------------------------------------
    def set_start(self, name: str, value: object) -> None:
        v = self.variables.get(name)
        if v is None:
            raise SystemDefinitionError(f"{self.name} has no variable {name!r}")
        self._call(f"setting {name}", "set_start", name, value)

    def initialize(self, start_time: float, stop_time: float) -> None:
        self.time = start_time
        self._call("initialisation", "initialize", start_time, stop_time)

    def bind(self, kind: str, inputs: np.ndarray, input_vrs: list[int],
             outputs: np.ndarray, output_vrs: list[int]) -> None:
        if input_vrs:
            self._inputs.append(inputs)
        if output_vrs:
            self._outputs.append((outputs, np.dtype(DTYPES[kind]), len(output_vrs)))
        self._call("binding", "bind", kind, list(input_vrs), list(output_vrs))

    # -- the loop ---------------------------------------------------------------------------------
    def write_inputs(self) -> None:
        self._pending = b"".join(buffer.tobytes() for buffer in self._inputs)

    def do_step(self, t: float, h: float) -> None:
        self.time = t
        self._fresh = None
        pending, self._pending = self._pending, None
        answer = self._exchange(_CALL_STEP + _STEP.pack(t, h) + (pending or b""), "fmi2DoStep", t + h)
        if answer[:1] == _ANSWER_OUTPUTS:
            self._fresh = answer[1:]
            self.time = t + h
            return
        self._answer(answer, "fmi2DoStep")
        self.time = t + h

    def read_outputs(self) -> None:
        data = self._fresh
        if data is None:
            self._call("reading the outputs", "read_outputs")
            data = self._fresh
            assert data is not None
        offset = 0
        for buffer, dtype, count in self._outputs:
            buffer[:] = np.frombuffer(data, dtype, count, offset)
            offset += count * dtype.itemsize

    def get(self, name: str) -> object:
        return self._call(f"reading {name}", "get", name)

    def reset(self) -> None:
        self._call("fmi2Reset", "reset")
        self.messages.clear()
        self._inputs.clear()
        self._outputs.clear()
        self._pending = self._fresh = None
        self.time = 0.0

    def terminate(self) -> None:
        """Terminate and free the instance, and let the child go (nothing to do after a crash)."""
        try:
            if self._crashed is None and self._process.poll() is None:
                try:
                    self._call("fmi2Terminate", "terminate")
                except FmuCrashed:
                    pass
                except SimulationError:
                    pass                    # freed all the same, as in process
        finally:
            self._close_pipes()
            if self._process.poll() is None:
                try:
                    self._process.wait(REAP_TIMEOUT)
                except subprocess.TimeoutExpired:
                    self._process.kill()
                    self._process.wait()
            if not self._mark.closed:
                self._mark.close()
            shutil.rmtree(self._workdir, ignore_errors=True)

    def _close_pipes(self) -> None:
        for connection in (self._calls, self._answers):
            if not connection.closed:
                connection.close()

    def __del__(self) -> None:          # a proxy dropped without terminate: the child must not outlive it
        process = getattr(self, "_process", None)
        if process is not None and process.poll() is None:
            self._close_pipes()


class IsolatedStatefulSlave(IsolatedSlave):
    """An isolated FMI 2.0 instance: its states stay in the child, the master holds handles of them."""

    def get_state(self) -> _RemoteState:
        return _RemoteState(self._call("fmi2GetFMUstate", "get_state"))

    def set_state(self, state: _RemoteState) -> None:
        self._call("fmi2SetFMUstate", "set_state", state.handle)

    def free_state(self, state: _RemoteState) -> None:
        self._call("fmi2FreeFMUstate", "free_state", state.handle)

    def serialize_state(self, state: _RemoteState) -> bytes:
        data = self._call("fmi2SerializeFMUstate", "serialize_state", state.handle)
        assert isinstance(data, bytes)
        return data

    def deserialize_state(self, data: bytes) -> _RemoteState:
        return _RemoteState(self._call("fmi2DeSerializeFMUstate", "deserialize_state", data=bytes(data)))


def isolated_slave(unpacked: UnpackedFmu, instance_name: str) -> IsolatedSlave:
    """The proxy of an instance of ``unpacked`` run in a child process that loads it from the folder it is unpacked
    in (FMI 2.0 instances save states)."""
    cls = IsolatedSlave if unpacked.fmi3 else IsolatedStatefulSlave
    return cls(unpacked.directory, instance_name, unpacked.variables)


# -- the child's side ----------------------------------------------------------------------------------------
class _Child:
    """The child's loop: one slave, driven by the calls that come down the pipe."""

    def __init__(self, calls: _Pipe, answers: _Pipe, mark: mmap.mmap, directory: str,
                 instance_name: str) -> None:
        self.calls, self.answers, self.mark = calls, answers, mark
        self.directory, self.instance_name = Path(directory), instance_name
        self.slave: Any = None
        self.said = 0                      # messages of the slave already sent
        self.inputs: list[tuple[np.ndarray, str]] = []
        self.outputs: list[np.ndarray] = []
        self.output_kinds: list[str] = []
        self.states: dict[int, object] = {}
        self.fmi = "fmi2"
        self._marks: dict[str, bytes] = {}

    def note(self, call: str) -> None:
        """Name the FMI call about to be made, where the master reads it if this process dies in it."""
        mark = self._marks.get(call)
        if mark is None:
            mark = self._marks[call] = call.encode()[:MARK_SIZE].ljust(MARK_SIZE, b"\0")
        self.mark[:] = mark

    def kinds(self, what: str, kinds: list[str]) -> str:
        return " / ".join(f"{self.fmi}{what}{k if self.fmi == 'fmi2' else _FMI3_NAMES[k]}" for k in kinds) \
            or f"{self.fmi}{what}"

    def take_inputs(self, data: bytes) -> None:
        offset = 0
        for buffer, _kind in self.inputs:
            n = buffer.nbytes
            buffer[:] = np.frombuffer(data, buffer.dtype, len(buffer), offset)
            offset += n

    def write_inputs(self) -> None:
        self.note(self.kinds("Set", [kind for _b, kind in self.inputs]))
        self.slave.write_inputs()

    def read_outputs(self) -> bytes:
        for kind in self.output_kinds:          # kind by kind: the mark names the very call
            self.note(self.kinds("Get", [kind]))
            self.slave.read_kind(kind)
        return b"".join(buffer.tobytes() for buffer in self.outputs)

    def news(self) -> list[tuple[str, str]]:
        messages = self.slave.messages if self.slave is not None else []
        new = messages[self.said:]
        self.said = len(messages)
        return new

    def send(self, body: dict[str, Any], *frames: bytes) -> None:
        self.answers.send_bytes(_ANSWER_JSON + json.dumps(body).encode())
        for frame in frames:
            self.answers.send_bytes(frame)

    def serve(self) -> None:
        while True:
            try:
                frame = self.calls.recv_bytes()
            except (EOFError, OSError):
                return                         # the master went away: so does this process
            if frame[:1] == _CALL_STEP:
                self.step(frame)
                continue
            call = json.loads(frame[1:])
            inputs = self.calls.recv_bytes() if call["inputs"] else None
            data = self.calls.recv_bytes() if call["data"] else None
            frames: list[bytes] = []
            body: dict[str, Any] = {}
            try:
                if inputs is not None:
                    self.take_inputs(inputs)
                    self.write_inputs()
                value = self.dispatch(call["op"], [_unplain(a) for a in call["args"]], data)
                if call["op"] == "read_outputs":
                    assert isinstance(value, bytes)
                    body["outputs"] = True
                    frames.append(value)
                elif isinstance(value, bytes):
                    body["binary"] = True
                    frames.append(value)
                else:
                    body["value"] = _plain(value)
            except Exception as err:
                body = {"error": _error_to_json(err, self.instance_name)}
            body["messages"] = self.news()
            self.note("")
            self.send(body, *frames)
            if call["op"] == "terminate":
                return

    def step(self, frame: bytes) -> None:
        t, h = _STEP.unpack_from(frame, 1)
        try:
            if len(frame) > 1 + _STEP.size:
                self.take_inputs(frame[1 + _STEP.size:])
                self.write_inputs()
            self.note(f"{self.fmi}DoStep")
            self.slave.do_step(t, h)
            outputs = self.read_outputs()
        except Exception as err:
            self.note("")
            self.send({"error": _error_to_json(err, self.instance_name), "messages": self.news()})
            return
        self.note("")
        if len(self.slave.messages) != self.said:
            self.send({"outputs": True, "messages": self.news()}, outputs)
        else:
            self.answers.send_bytes(_ANSWER_OUTPUTS + outputs)

    def dispatch(self, op: str, args: list[Any], data: bytes | None) -> object:
        if op == "instantiate":
            from .instances import make_slave
            unpacked = UnpackedFmu(self.directory)
            self.fmi = "fmi3" if unpacked.fmi3 else "fmi2"
            self.note(f"{self.fmi}Instantiate")
            self.slave = make_slave(unpacked, self.instance_name)
            return None
        slave = self.slave
        if op == "set_start":
            v = slave.variables[args[0]]
            self.note(f"{self.fmi}Set{v.type if self.fmi == 'fmi2' else _FMI3_NAMES.get(v.type, v.type)}")
            return slave.set_start(args[0], args[1])
        if op == "initialize":
            self.note(f"{self.fmi}EnterInitializationMode / {self.fmi}ExitInitializationMode")
            return slave.initialize(args[0], args[1])
        if op == "bind":
            kind, input_vrs, output_vrs = args
            dtype = DTYPES[kind]
            inputs, outputs = np.zeros(len(input_vrs), dtype), np.zeros(len(output_vrs), dtype)
            if input_vrs:
                self.inputs.append((inputs, kind))
            if output_vrs:
                self.outputs.append(outputs)
                self.output_kinds.append(kind)
            return slave.bind(kind, inputs, input_vrs, outputs, output_vrs)
        if op == "read_outputs":
            return self.read_outputs()
        if op == "get":
            v = slave.variables[args[0]]
            self.note(f"{self.fmi}Get{v.type if self.fmi == 'fmi2' else _FMI3_NAMES.get(v.type, v.type)}")
            return slave.get(args[0])
        if op == "reset":
            self.note(f"{self.fmi}Reset")
            slave.reset()
            self.said = 0
            self.inputs.clear()
            self.outputs.clear()
            self.output_kinds.clear()
            return None
        if op == "terminate":
            self.note(f"{self.fmi}Terminate / {self.fmi}FreeInstance")
            return slave.terminate()
        return self.dispatch_state(op, args, data)

    def dispatch_state(self, op: str, args: list[Any], data: bytes | None) -> object:
        slave = self.slave
        if op == "get_state":
            self.note("fmi2GetFMUstate")
            handle = max(self.states, default=0) + 1
            self.states[handle] = slave.get_state()
            return handle
        if op == "deserialize_state":
            self.note("fmi2DeSerializeFMUstate")
            handle = max(self.states, default=0) + 1
            self.states[handle] = slave.deserialize_state(data)
            return handle
        state = self.states[args[0]]
        if op == "set_state":
            self.note("fmi2SetFMUstate")
            return slave.set_state(state)
        if op == "free_state":
            self.note("fmi2FreeFMUstate")
            del self.states[args[0]]
            return slave.free_state(state)
        if op == "serialize_state":
            self.note("fmi2SerializeFMUstate")
            return slave.serialize_state(state)
        raise SimulationError(f"{self.instance_name}: no call {op!r} in the FMU's process")


#: The master's kinds by their FMI 3.0 names (for the call a crash is named by)
_FMI3_NAMES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}


def main(argv: list[str]) -> None:
    calls_fd, answers_fd, mark_fd = (int(a) for a in argv[:3])
    directory, instance_name = argv[3:5]
    signal.signal(signal.SIGINT, signal.SIG_IGN)    # Ctrl-C is the master's to handle: it ends this process
    mark = mmap.mmap(mark_fd, MARK_SIZE)
    os.close(mark_fd)
    child = _Child(_Pipe(calls_fd), _Pipe(answers_fd), mark, directory,
                   instance_name)
    try:
        child.serve()
    except BrokenPipeError:
        pass                                        # the master went away mid-answer


if __name__ == "__main__":
    main(sys.argv[1:])
