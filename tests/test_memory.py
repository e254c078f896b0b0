"""Memory stays flat over many runs in one process: no copies of the FMU libraries, no sys.path
entries and no more than 5 MB of RSS pile up over 40 runs of ``simulate()``. Measured in a fresh process."""

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

    for _ in range(5):                                    # warm-up: first imports, first loads
        simulate("lathe_taper", stop_time=0.1)
    rss, path, maps = rss_mb(), len(sys.path), deleted_maps()
    for _ in range(40):
        r = simulate("lathe_taper", stop_time=0.1)
    assert r["seq.subcycle"].max() == 1                   # the runs did run
    print("GROWTH", rss_mb() - rss, len(sys.path) - path, deleted_maps() - maps)
''')


def test_forty_runs_in_one_process_stay_flat(project):
    proc = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    rss, path, maps = [float(x) for x in proc.stdout.split("GROWTH")[1].split()]
    assert path == 0 and maps == 0
    assert rss < 5.0, f"RSS grew {rss:.1f} MB over 40 runs"
