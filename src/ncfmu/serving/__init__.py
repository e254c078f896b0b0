"""Live virtual commissioning: a system run in real time behind an OPC UA server (asyncua).

Two threads share the work, and neither waits on the other:

- the **simulation thread** owns the FMUs (every FMI call happens there). It paces simulated time to the
  wall clock (``speed`` 1 = real time, 0 = as fast as it can), runs the steps that are due in chunks, and
  between chunks applies the writes clients made (forcing an input, releasing it, a tunable parameter, Pause,
  Resume, Stop, Reset) and leaves a snapshot of the values for the server;
- the **server** (asyncua, on an asyncio loop in the main thread) publishes the newest snapshot every
  ``publish_interval`` (subscriptions then deliver data changes) and answers clients.

Each node of a Write is checked on the server side first (type, NaN/inf, the port's min/max from the
modelDescription: OPC UA status Bad_TypeMismatch, Bad_OutOfRange, Bad_NotWritable, Bad_NodeIdUnknown; that node
changes nothing), then handed to the simulation thread, which applies it before the next step and answers with
the session's verdict (a tunable parameter is first checked by its model's own rules on a copy; a refusal is
Bad_OutOfRange and never reaches the FMU). Each node gets its own status, as OPC UA Part 4 asks.

Address space (stable: PLC projects point at these names): namespace ``urn:ncfmu:<system>``; one Object per
component instance; one Variable per FMU variable, string NodeId ``<instance>.<variable>``, BrowseName the
variable's name, DataType Double/Int32/Boolean/String, its description, its unit as EngineeringUnits
(EUInformation); inputs also get ``<instance>.<variable>.forced`` (Boolean). The ``Simulation`` object holds
``time``, ``speed``, ``lag``, ``overruns``, ``state``, ``reason``, ``forced`` (the forced inputs), ``verdict``
(the part check's summary line when the last program ended: a lathe's or mill's done, a grinder's cycle end) and the
methods ``Pause``, ``Resume``, ``Stop``, ``Reset`` and ``Release(name)``.

With a watchdog (``--watchdog S``), a client session that forced inputs is lost when it closes or is silent S s.
As a CNC that loses its PLC or HMI link stops, ``--on-lost hold`` (the default) puts the machine in feed hold:
each feed-hold input (:data:`~ncfmu.serving.runner.FEED_HOLD_INPUT`) forced true, the simulation running on (a
system without one halts: a stop), the lost session's forces kept, ``Simulation.state`` ``held`` and
``Simulation.reason`` which session was lost and what is held. Those inputs cannot be forced or released one by
one meanwhile (Bad_InvalidState); a client's ``Resume`` -- the cycle start after a feed hold -- releases them all
and the machine moves on (Reset starts again). ``--on-lost release`` lets the lost session's forces fall back
at once instead.

A crash is published as it happens (a system with a part check: the lathes, the mill): the simulation thread
hands the recorded rows to the part check every :data:`CRASH_CHECK` s of simulated time; the check runs in a
third thread (``ncfmu-part-check``), at most one hand-over behind (at --speed 0 each is waited for); at the first
crash the simulation halts (above speed 0 up to one hand-over later; the crash's time, line and depth are those
of the rows up to the halt, as a synchronous check has them), as a machine's collision monitor stops it --
``Simulation.state`` ``crashed``, ``Simulation.reason`` and ``Simulation.crash`` the crash (time, program line,
what, how deep), ``Simulation.crashes`` how many -- and the ``Simulation`` object emits a ``CrashEventType``
event (Message the same text, Severity 900, and the fields ``SimulationTime``, ``Line``, ``What``, ``DepthMm``).
Reset starts again; Resume is refused.

Another front end beside the OPC UA server (a web page) reads the values with
:meth:`~ncfmu.serving.runner.Runner.latest` (never taking the server's snapshot) and acts with
:meth:`~ncfmu.serving.server.LiveServer.write`, :meth:`~ncfmu.serving.server.LiveServer.call` and
:meth:`~ncfmu.serving.server.LiveServer.release` on the server's event loop: the very code the OPC UA Write and the
``Simulation`` methods run, with the same checks and refusals.

The package, by concern (each module imports only those listed above it; tests/serve/test_serve_package.py holds
them to it):

- :mod:`~ncfmu.serving.address_space` -- the served variables (:class:`Point`) and the check of a write;
- :mod:`~ncfmu.serving.recording` -- the recording of a served run (``--out``);
- :mod:`~ncfmu.serving.crash_watch` -- the part check's thread: crashes and verdicts as they happen;
- :mod:`~ncfmu.serving.runner` -- the simulation thread (:class:`Runner`), which knows nothing of OPC UA;
- :mod:`~ncfmu.serving.cnc_model` -- the OPC 40502 companion model;
- :mod:`~ncfmu.serving.security` -- who may connect, the server's certificate;
- :mod:`~ncfmu.serving.server` -- the OPC UA server (:class:`LiveServer`) and :func:`serve`.
"""

from __future__ import annotations

from .address_space import Point, WriteRefused, check_value, points_of
from .cnc_model import build_cnc_model, cnc_types_xml
from .crash_watch import CRASH_CHECK, CrashWatch
from .recording import Recorder
from .runner import ENDED_BADLY, FAST_CHUNK, MAX_CHUNK_WALL, PaceStats, Runner, Snapshot
from .security import APPLICATION_URI, Security, check_endpoint, make_certificate
from .server import CRASH_SEVERITY, DEFAULT_ENDPOINT, LiveServer, ServeSummary, serve

__all__ = ["APPLICATION_URI", "CRASH_CHECK", "CRASH_SEVERITY", "DEFAULT_ENDPOINT", "ENDED_BADLY", "FAST_CHUNK",
           "MAX_CHUNK_WALL", "CrashWatch", "LiveServer", "PaceStats", "Point", "Recorder", "Runner", "Security",
           "ServeSummary", "Snapshot", "WriteRefused", "build_cnc_model", "check_endpoint", "check_value",
           "cnc_types_xml", "make_certificate", "points_of", "serve"]

