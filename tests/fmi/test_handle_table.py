"""The live-instance table of the C layer (fmi2_machine.h), read without its lock by every FMI call's lookup.

A lookup on one thread while fmi2Instantiate on another outgrows the table reads only entries of the table it
read: tests/native/handle_table_probe.c makes that interleaving deterministic (the other thread's change runs
within the lookup's load of the table or of its count) and is built with AddressSanitizer, which ends the process
at any read beyond a table. With real threads, lookups racing fmi2Instantiate and fmi2FreeInstance find each live
instance and no other.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

PROBE_C = Path(__file__).resolve().parents[1] / "native" / "handle_table_probe.c"
LAYER_C = Path(__file__).resolve().parents[2] / "src" / "ncfmu" / "fmi" / "c"


@pytest.fixture(scope="module")
def probe(tmp_path_factory) -> Path:
    from ncfmu.fmi.builder import fmi_headers
    exe = tmp_path_factory.mktemp("probe") / "handle_table_probe"
    subprocess.run(["cc", "-std=c11", "-D_DEFAULT_SOURCE", "-O1", "-g", "-fsanitize=address", "-Wall", "-Werror",
                    f"-I{fmi_headers()}", f"-I{LAYER_C}", "-o", str(exe), str(PROBE_C), "-lpthread", "-ldl"],
                   check=True)
    return exe


@pytest.mark.parametrize("changed_before_load_of", ["live", "n"])
def test_a_lookup_while_another_thread_outgrows_the_table_reads_within_it(probe, changed_before_load_of):
    # outgrown tables stay allocated by design (a lookup may still read one): not a leak to report
    env = dict(os.environ, ASAN_OPTIONS="detect_leaks=0")
    run = subprocess.run([str(probe), changed_before_load_of], capture_output=True, text=True, env=env, timeout=60)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout == "table of 8 outgrown during a lookup: no read beyond it\n"


def test_lookups_racing_instantiate_and_free_on_other_threads_find_each_live_instance(probe):
    env = dict(os.environ, ASAN_OPTIONS="detect_leaks=0")
    run = subprocess.run([str(probe), "threads"], capture_output=True, text=True, env=env, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout == "0 wrong lookups\n"
