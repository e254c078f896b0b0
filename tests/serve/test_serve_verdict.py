"""``ncfmu serve`` says the part check's verdict when a program ends: ``Simulation.verdict`` holds the summary
line, and the line is printed. The oracle: ``ncfmu run``'s part check of the same program."""

from __future__ import annotations

import re

import numpy as np
import pytest
from serve_plc import connect, run

pytestmark = pytest.mark.slow


def test_the_part_verdict_is_published_and_printed_when_the_program_ends(ncfmu_serve, lathe_taper):
    served = ncfmu_serve("lathe_taper", "--speed", "0")        # the defaults: with the OPC 40502 model

    async def plc():
        async with connect(served) as p:
            cnc = await p.client.nodes.objects.get_child([f"{p.idx}:CncInterface"])
            assert cnc.nodeid == p.node("Cnc").nodeid
            text = await p.wait_until("Simulation.verdict", lambda v: v != "", timeout=60)
            await p.call("Stop")
            return text
    text = run(plc())
    assert served.wait(30) == 0, served.output
    # the same part as `ncfmu run` judges: within the tolerance, the same stock left and gouge (the removal
    # engine's figures move by 1e-4 mm with how the rows are chunked: the served check gets 50 rows at a time)
    oracle = lathe_taper.part.verdict()
    assert oracle.within_tolerance is True
    said = re.fullmatch(r"part: within 0\.0100 mm: left <= (\S+) mm, gouge <= (\S+) mm", text)
    assert said is not None, text
    assert float(said[1]) == pytest.approx(oracle.max_left_mm, abs=5e-4)
    assert float(said[2]) == pytest.approx(oracle.max_gouge_mm, abs=5e-4)
    done = lathe_taper["seq.done"].astype(bool)
    end = float(lathe_taper.time[np.argmax(done)])              # the program's end: the sequencer says done
    printed = [line for line in served.lines if "program ended" in line]
    assert printed == [f"ncfmu serve: program ended at t = {end:.3f} s: {text}"], served.output
