"""A served run (the OPC UA server's simulation thread, no server) of a system whose foreign axis crashes, in a
process of its own: on a master that runs foreign FMUs in process, the crash takes this process down.

    python crash_host.py ARCHIVE OUT CRASH_AT

prints one JSON line: the runner's state and reason, the session's time and where its rows went.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

from ncfmu.project import OpenSystem
from ncfmu.serving import ENDED_BADLY, Recorder, Runner, points_of


def main(archive: str, out: str, crash_at: str) -> None:
    with OpenSystem(Path(archive)) as opened:
        recorder = Recorder(opened.system.name, Path(out))
        session = opened.open_session(stop_time=math.inf, start_values={"x_axis.crash_at": float(crash_at)},
                                      sinks=recorder.sinks())
        runner = Runner(session, points_of(opened.slaves), 0.0, recorder)
        runner.start()
        runner.thread.join(60)
        alive = runner.thread.is_alive()
        if alive:
            runner.stop("the test's time is over")
            runner.thread.join(10)
        # as serve() closes a served run: complete unless the simulation failed or faulted
        session.close(complete=runner.state not in ENDED_BADLY, reason=runner.reason)
        recorder.end_segment(list(session.writes), final=True, start=runner.start_time)
        print(json.dumps({"state": runner.state, "reason": runner.reason, "time": float(session.time),
                          "timed_out": alive, "files": [str(f) for f in recorder.files]}))


if __name__ == "__main__":
    main(*sys.argv[1:4])
