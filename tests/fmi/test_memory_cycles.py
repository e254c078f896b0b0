"""Memory stays flat when a host instantiates an FMU again and again (a test bench, a sweep worker): 200
instantiate / step / get-set-serialize state / free cycles of each FMU, in a fresh process
(tests/fmi/memory_cycles.py), grow RSS by less than 1 MB after a warm-up of 150 cycles (first imports,
the allocators' arenas). Before the shim drove the Python slave itself, pythonfmu's library ran the model
script again at every fmi2Instantiate and the namespaces were kept: 5 to 7 KB a cycle."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow        # a fresh process and 350 cycles per FMU

CYCLES = Path(__file__).with_name("memory_cycles.py")
FMUS = ["AreaLimiter", "ContourInterpolator", "CutSequencer", "OperatorPanel", "ProgrammableFeed", "ServoAxis",
        "SpindleDrive"]


@pytest.mark.parametrize("model", FMUS)
def test_two_hundred_cycles_grow_less_than_a_megabyte(fmus, model):
    proc = subprocess.run([sys.executable, str(CYCLES), str(fmus[model]), "150", "200"], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    before, after = map(int, proc.stdout.split("RSS")[1].split())
    print(f"{model}: RSS {before} KiB -> {after} KiB over 200 cycles ({(after - before) / 200:.2f} KiB a cycle)")
    assert after - before < 1024
