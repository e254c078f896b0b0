"""Memory stays flat over many runs in one process: no copies of the FMU libraries, no sys.path entries and
less than 1 MB of RSS pile up over 200 runs of ``simulate()`` after a warm-up. Measured in a fresh process.
(Each FMU's own instantiate/free cycles: tests/fmi/test_memory_cycles.py.)

CPython's table of interned strings doubles once when the names the imports intern cross its threshold (2^16 ->
2^17 slots: one 1.9 MB allocation, its pages touched as strings come) -- bookkeeping of the interpreter, not a
pile-up of ours, and whether it falls inside the 200 runs depends only on how many names the package interns (in
2026-12 the merged package put it at run ~195: 1.4 MB "grown"). The warm-up therefore interns 20 000 names of its
own first, so the table has its size before the measurement starts (measured then: 320 KiB over 200 runs, where
9c586ec grew 64 KiB -- the difference is not yet explained, and the limit stays 1 MB)."""

import subprocess
import sys
import textwrap

import pytest

pytestmark = pytest.mark.slow        # whole systems in closed loop: not in the fast subset

SCRIPT = textwrap.dedent('''
    import sys
    from ncfmu.project import simulate

    def rss_mb():
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("VmRSS")) / 1024

    def deleted_maps():
        with open("/proc/self/maps") as f:
            return sum(1 for line in f if "(deleted)" in line)

    interned = [sys.intern(f"warm-up {i}") for i in range(20000)]   # the intern table grown now (see above)
    for _ in range(40):                                   # warm-up: first imports, first loads, the arenas
        simulate("lathe_taper", stop_time=0.1)
    rss, path, maps = rss_mb(), len(sys.path), deleted_maps()
    for _ in range(200):
        r = simulate("lathe_taper", stop_time=0.1)
    assert r["seq.subcycle"].max() == 1                   # the runs did run
    print("GROWTH", rss_mb() - rss, len(sys.path) - path, deleted_maps() - maps)
''')


def test_two_hundred_runs_in_one_process_stay_flat(project):
    proc = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    rss, path, maps = [float(x) for x in proc.stdout.split("GROWTH")[1].split()]
    assert path == 0 and maps == 0
    print(f"lathe_taper: RSS grew {rss * 1024:.0f} KiB over 200 runs")
    assert rss < 1.0, f"RSS grew {rss:.2f} MB over 200 runs"
