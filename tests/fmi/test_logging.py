"""Reasons reach the user in any FMI tool: a Python FMU sends errors and warnings (a refused parameter, an
alarm) to the host's logger whatever the debug-logging setting, as the Reference-FMUs do; info messages
only with debug logging on. Checked through fmpy, a real FMI host, with its own logger callback."""

from __future__ import annotations

import tempfile
from ctypes import byref

import fmpy.fmi2 as fmi2
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.logging import addLoggerProxy

# Each controller FMU, and the position input whose NaN is an alarm (the panel has no inputs to alarm on).
ALARM_INPUT = {"AreaLimiter": "ref_pos", "ContourInterpolator": "x_pos", "CutSequencer": "x_pos",
               "OperatorPanel": None, "ProgrammableFeed": "x_pos"}


# fmpy's C proxy that formats the variadic message (addLoggerProxy) forwards to ONE logger per process, the
# last one registered: a logger made per instance dangles once its instance is gone, and the next FMU that logs
# through fmpy's default callbacks calls freed memory (it crashed a later test). So one logger lives as long as
# the process and routes each message by the componentEnvironment its host registered.
_LOGS: dict[int, list[tuple[int, str]]] = {}


def _dispatch(env, name, status, category, message) -> None:
    log = _LOGS.get(env or 0)
    if log is not None:
        log.append((status, message.decode()))


_LOGGER = fmi2.fmi2CallbackLoggerTYPE(_dispatch)


class Host:
    """One instance of an FMU in fmpy's FMU2Slave, its log kept as (status, message)."""

    def __init__(self, fmu, debug_logging: bool):
        self.log: list[tuple[int, str]] = []
        _LOGS[id(self)] = self.log
        self.callbacks = fmi2.fmi2CallbackFunctions()
        self.callbacks.logger = _LOGGER
        self.callbacks.componentEnvironment = id(self)
        self.callbacks.allocateMemory = fmi2.defaultCallbacks.allocateMemory
        self.callbacks.freeMemory = fmi2.defaultCallbacks.freeMemory
        addLoggerProxy(byref(self.callbacks))          # formats printf-style messages, as fmpy's own logger does
        md = read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.params = md.modelVariables
        self.fmu = fmi2.FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu), tempfile.mkdtemp()),
                                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="dut")
        self.fmu.instantiate(loggingOn=debug_logging, callbacks=self.callbacks)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.t = 0.0

    def steps(self, n: int) -> None:
        for _ in range(n):
            self.fmu.doStep(self.t, 1e-3)
            self.t += 1e-3

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


def test_a_refused_parameter_reaches_fmpys_logger_with_debug_logging_off(fmus):
    """The FMU's user's first contact: `block[1].Xd = -0.5` in fmpy's simulate_fmu, debug logging off."""
    said: list[tuple[int, str]] = []
    with pytest.raises(Exception, match="fmi2ExitInitializationMode"):
        simulate_fmu(str(fmus["CutSequencer"]), stop_time=0.01, start_values={"block[1].Xd": -0.5},
                     debug_logging=False, logger=lambda c, name, status, category, message:
                     said.append((status, message.decode())))
    assert said == [(3, "CutSequencer: parameter refused: block[1].Xd = -0.5: must be > 0")]


@pytest.mark.parametrize("model", sorted(ALARM_INPUT))
def test_refusal_and_alarm_reasons_reach_the_logger_without_debug_logging(fmus, model):
    host = Host(fmus[model], debug_logging=False)
    real_parameter = next(v.name for v in host.params if v.causality == "parameter" and v.type == "Real")
    host.fmu.setReal([host.vr[real_parameter]], [float("nan")])
    with pytest.raises(FMICallException):
        host.fmu.exitInitializationMode()
    assert host.log == [(3, f"dut: parameter refused: {real_parameter} = nan: must be finite")]
    host.fmu.reset()
    host.fmu.setupExperiment(startTime=0.0)
    host.fmu.enterInitializationMode()
    host.fmu.exitInitializationMode()
    host.log.clear()
    if ALARM_INPUT[model]:
        host.steps(3)
        host.fmu.setReal([host.vr[ALARM_INPUT[model]]], [float("nan")])
        host.steps(3)
        assert len(host.log) == 1 and host.log[0][0] == 3, host.log
        assert f"t = 0.0030 s: input {ALARM_INPUT[model]} = nan: must be finite" in host.log[0][1]
        assert host.fmu.getBoolean([host.vr["alarm"]]) == [True]
    host.close()


@pytest.mark.parametrize("debug_logging", [False, True])
def test_info_messages_reach_the_logger_only_with_debug_logging_on(fmus, debug_logging):
    host = Host(fmus["AreaLimiter"], debug_logging=debug_logging)
    host.fmu.exitInitializationMode()
    host.fmu.setReal([host.vr["ref_pos"]], [float("nan")])
    host.steps(2)
    host.fmu.setReal([host.vr["ref_pos"]], [0.0])
    host.steps(2)
    info = [m for s, m in host.log if s == 0]
    assert [s for s, _ in host.log if s != 0] == [3]                 # the alarm: always
    assert info == (["dut: t = 0.0020 s: inputs sane again; following the commands"] if debug_logging else [])
    host.close()


@pytest.mark.parametrize("model", ["ContourInterpolator", "CutSequencer"])
def test_warnings_reach_the_logger_without_debug_logging(fmus, model):
    host = Host(fmus[model], debug_logging=False)
    host.fmu.exitInitializationMode()
    host.fmu.setReal([host.vr["feed_override"]], [3.0])
    host.fmu.setBoolean([host.vr["start"]], [True])                # the override is read while a cycle runs
    host.steps(3)
    warnings = [m for s, m in host.log if s == 1]
    assert len(warnings) == 1 and "input feed_override = 3.0: outside 0..1.5, clamped to 1.5" in warnings[0]
    host.close()


def test_the_native_servo_logs_errors_and_warnings_whatever_the_debug_logging(fmus):
    """ServoAxis (C, no Python) tells its reasons as the Python FMUs do: a refused parameter and a non-finite
    command reach the logger with debug logging off; fmi2SetDebugLogging takes the declared categories only."""
    host = Host(fmus["ServoAxis"], debug_logging=False)
    with pytest.raises(FMICallException):
        host.fmu.setReal([host.vr["Kv"]], [float("nan")])
    assert host.log == [(3, "Kv = nan: must be finite")]
    host.fmu.setDebugLogging(False, [])
    host.fmu.exitInitializationMode()
    host.log.clear()
    host.steps(3)
    host.fmu.setReal([host.vr["pos_cmd"]], [float("nan")])
    host.steps(3)                                                      # said once, not every step
    assert host.log == [(1, "t = 0.0030 s: pos_cmd = nan is not finite; holding the last command")]
    host.log.clear()
    host.fmu.setDebugLogging(True, ["logStatusWarning", "logAll"])
    with pytest.raises(FMICallException):
        host.fmu.setDebugLogging(True, ["verbose"])
    assert len(host.log) == 1 and host.log[0][0] == 3 and "verbose is not a log category" in host.log[0][1]
    host.close()
    # the categories it takes are the ones its modelDescription declares (those of the Python FMUs)
    declared = [c.name for c in read_model_description(str(fmus["ServoAxis"])).logCategories]
    assert declared == ["logStatusWarning", "logStatusDiscard", "logStatusError", "logStatusFatal", "logAll"]
    assert declared == [c.name for c in read_model_description(str(fmus["CutSequencer"])).logCategories]


def test_the_log_is_taken_only_when_something_was_logged(fmus, monkeypatch):
    """The binary reads the length of the slave's pending_log (a C call) after every call, and calls
    fmi_take_log only when it is not empty: a quiet run makes no such call (before: about five a step), and
    what is logged still reaches the logger, once."""
    import sys

    from ncfmu.fmi.builder import vendored_package

    host = Host(fmus["CutSequencer"], debug_logging=False)
    adapter = sys.modules[f"{vendored_package(fmus['CutSequencer'])}.fmi.adapter"]   # the FMU's own copy
    calls = []
    take = adapter.ControllerSlave.fmi_take_log

    def counted(self):
        calls.append([m.msg for m in self.pending_log])
        return take(self)

    monkeypatch.setattr(adapter.ControllerSlave, "fmi_take_log", counted)
    host.fmu.exitInitializationMode()
    commands = host.fmu.getReal([host.vr["x_cmd"], host.vr["z_cmd"]])
    for _ in range(50):                         # the master's calls of a quiet step: the axes follow the commands
        host.fmu.setReal([host.vr["x_pos"], host.vr["z_pos"]], commands)
        host.steps(1)
        commands = host.fmu.getReal([host.vr["x_cmd"], host.vr["z_cmd"]])
        host.fmu.getBoolean([host.vr["busy"], host.vr["alarm"]])
    assert calls == [] and host.log == []
    host.fmu.setReal([host.vr["x_pos"]], [float("nan")])              # an alarm: logged, taken, said once
    host.steps(3)
    assert len(calls) == 1 and len(host.log) == 1 and host.log[0][0] == 3, (calls, host.log)
    host.close()
