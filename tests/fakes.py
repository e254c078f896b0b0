"""What tests share besides fixtures: fake slaves the master drives without any FMU, and system variants."""

from dataclasses import replace

from ncfmu.cosim.master import Master
from ncfmu.cosim.slave import Variable
from ncfmu.cosim.ssp import Component, Connection, System


class FakeSlave:
    """y = u + 1 (a counter chain), checking the documented call order."""

    def __init__(self, name, log):
        self.name, self.log = name, log
        self.variables = {"u": Variable("u", "Real", "input", 0), "y": Variable("y", "Real", "output", 1),
                          "k": Variable("k", "Real", "parameter", 2)}
        self.u = self.y = 0.0
        self.k = 1.0
        self.state = "instantiated"
        self.messages: list[tuple[str, str]] = []

    def set_start(self, name, value):
        assert self.state == "instantiated"
        setattr(self, name, value)

    def initialize(self, t0, stop):
        assert self.state == "instantiated"
        self.state = "initialized"

    def bind(self, kind, inputs, input_vrs, outputs, output_vrs):
        assert self.state == "initialized"
        if kind == "Real":
            self.inbuf, self.outbuf = inputs, outputs

    def write_inputs(self):
        if len(self.inbuf):
            self.u = float(self.inbuf[0])

    def do_step(self, t, h):
        self.log.append(self.name)
        self.y = self.u + self.k

    def read_outputs(self):
        self.outbuf[0] = self.y

    def terminate(self):
        self.state = "terminated"


def chain(mode):
    """Two fake slaves in a loop (a.y -> b.u, b.y -> a.u) under a Master in ``mode``; the master and the step log."""
    log = []
    a, b = FakeSlave("a", log), FakeSlave("b", log)
    system = System("chain", [Component("a", "Fake"), Component("b", "Fake", {"k": 10.0})],
                    [Connection("a", "y", "b", "u"), Connection("b", "y", "a", "u")], stop_time=0.003)
    m = Master(system, [a, b], mode)
    return m, log


def unwired(name, folder):
    """``name`` with the limiter's alarm not wired to the controller (seq.alarm_in is free for an input CSV)."""
    from ncfmu.cosim.ssp import pack, write_system
    from ncfmu.project import project_root
    from ncfmu.systems import get_system
    system = get_system(name)
    system = replace(system, name=f"{name}_unwired",
                     connections=[c for c in system.connections
                                  if (c.start_element, c.start_connector) != ("limiter", "alarm")])
    return pack(write_system(system, folder), project_root() / "fmus", folder / f"{name}_unwired.ssp")
