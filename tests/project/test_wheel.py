"""The wheel works -- installed (not editable) into a fresh venv, `ncfmu run` from a folder outside the
checkout builds its FMUs into the user cache and runs a system closed loop."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_wheel_in_a_fresh_venv_runs_a_system_outside_the_checkout(tmp_path):
    dist, venv, work, cache = (tmp_path / d for d in ("dist", "venv", "work", "cache"))
    # nothing of the caller's environment points into the checkout (a PYTHONPATH to src/ would make the venv's
    # pip see ncfmu as installed already, and skip the wheel)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NCFMU_", "PYTHON", "VIRTUAL_ENV"))}
    env["XDG_CACHE_HOME"] = str(cache)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(dist), str(ROOT)],
                   check=True, timeout=600, capture_output=True)
    (wheel,) = dist.glob("ncfmu-*.whl")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    subprocess.run([str(venv / "bin" / "pip"), "install", "-q", str(wheel)], check=True, timeout=900,
                   capture_output=True, env=env)
    work.mkdir()
    done = subprocess.run([str(venv / "bin" / "ncfmu"), "run", "grinder_feed", "--out", "out"],
                          cwd=work, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    # the package came from the venv, not from the checkout
    where = subprocess.run([str(venv / "bin" / "python"), "-c", "import ncfmu; print(ncfmu.__file__)"],
                           cwd=work, env=env, capture_output=True, text=True, check=True).stdout
    assert str(venv) in where and str(ROOT) not in where
    # built artefacts in the documented place: the user cache, per version
    (built,) = (cache / "ncfmu").iterdir()
    assert {p.name for p in (built / "fmus").glob("*.fmu")} == {
        "AreaLimiter.fmu", "ContourInterpolator.fmu", "CutSequencer.fmu", "OperatorPanel.fmu",
        "ProgrammableFeed.fmu", "ServoAxis.fmu", "SpindleDrive.fmu"}
    assert (built / "ssp" / "grinder_feed.ssp").is_file() and not (built / "docs").exists()
    assert len(list((built / "build").glob("ncfmu_loop-*.so"))) == 1       # the master's C loop, built there too
    # the run itself: the seed's cycle ground to 4.3 mm (rapid 4.0, rough 0.2, fine 0.1) and returned
    lines = done.stdout.splitlines()
    assert lines[0].startswith("system grinder_feed: simulated")
    assert "deepest X: 4.3000 mm" in done.stdout
    # the run ends at the cycle's end (RUN falls: the return commanded to the origin), the axis settling within its
    # in-position band (5 um) -- a fraction of a micrometre from 0
    at_end = re.search(r"X at the end (-?\d+\.\d+) mm", done.stdout)
    assert at_end is not None and abs(float(at_end.group(1))) <= 0.001, done.stdout
    assert "alarm: no" in done.stdout
    assert not any(line.startswith("--") for line in lines)            # no build chatter among the summary
    assert (work / "out" / "grinder_feed.csv").is_file()
