"""Runs end where the work ends, with exit statuses a CI job can gate on (issue 51, part B).

``ncfmu run`` stops when the system's done signal says the cycle is done (the last row within a second of it), when
the part check sees a crash or an alarm halts the machine; ``--stop-time`` is the limit. Exit status 0 done and
judged good, 3 a crash or a part out of tolerance, 4 not finished (the limit, an alarm, not judged), 2 refused.
``ncfmu sweep`` judges each variant the same way (``crashed``, ``out_of_tolerance``, ``unfinished``) and exits 3
or 4; ``--set`` gives every variant the same values.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from ncfmu.cli import main
from ncfmu.exitcodes import EXIT_NOT_FINISHED, EXIT_OK, EXIT_PART_REJECTED, EXIT_REFUSED

pytestmark = pytest.mark.slow        # whole systems in closed loop


def _times(csv_path: Path) -> np.ndarray:
    return np.loadtxt(csv_path, delimiter=",", skiprows=1, usecols=0, ndmin=1)


def test_a_program_longer_than_the_old_default_stop_time_finishes_and_is_judged(project, tmp_path, capsys):
    """lathe_roughing with its finish pass at 1.5 mm/s instead of 2: the cycle needs ~99.9 s, beyond the system's
    95 s. Without --stop-time the run goes on to the end of the cycle, is judged, and stops within a second."""
    rc = main(["run", "lathe_roughing", "--set", "seq.block[2].feed=1.5", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == EXIT_OK, out
    part = json.loads((tmp_path / "lathe_roughing.part.json").read_text())
    assert part["within_tolerance"] is True and part["not_judged"] is None
    done = float(out.split("cycle done: ")[1].split(" s")[0])
    # 6 roughing passes and the finish pass (42 mm at 1.5 mm/s instead of 2: 7 s longer than the 92.885 s of 2)
    assert done == pytest.approx(92.885 + 42 / 1.5 - 42 / 2, abs=0.05)
    t = _times(tmp_path / "lathe_roughing.csv")
    assert done < t[-1] <= done + 1.0
    assert "ended: done" in out


def test_a_stop_time_short_of_the_work_exits_4(project, tmp_path, capsys):
    rc = main(["run", "grinder_feed", "--stop-time", "2", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == EXIT_NOT_FINISHED, out
    assert "ended: the --stop-time limit 2 s reached" in out
    assert _times(tmp_path / "grinder_feed.csv")[-1] == pytest.approx(2.0)


def test_an_alarm_ends_the_run_and_exits_4(project, tmp_path, capsys):
    """The table sent back into the headstock zone with the wheel in: the limiter's alarm halts the machine at
    ~4 s; the run ends within a second of it (no --stop-time: the old one was 25 s)."""
    program = "M0: Y+D1F7; M1: X+D2F7; M2: Y-D6F7; M3: END; M41: XF7S1; M42: YF7S1; M43: END; M45: END"
    rc = main(["run", "grinder_envelope", "--set", f"feed.program={program}", "--set", "feed.D6=250",
               "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == EXIT_NOT_FINISHED, out
    alarm_at = float(out.split("ALARM from t = ")[1].split(" s")[0])
    t = _times(tmp_path / "grinder_envelope.csv")
    assert alarm_at < t[-1] <= alarm_at + 1.0
    assert "ended: alarm" in out


def test_a_part_out_of_tolerance_exits_3_and_a_refusal_2(project, tmp_path, capsys):
    """The grinder's size is 3.05 nm deep of the programmed X (the encoder counts 9.5 nm): judged against 1 nm,
    out of tolerance."""
    rc = main(["run", "grinder_feed", "--tolerance", "1e-6", "--set", "feed.T1=0.05", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == EXIT_PART_REJECTED, out
    assert "OUT OF TOLERANCE" in out and "out_of_tolerance: part out of tolerance" in out
    # done (31.025 s with the 0.05 s spark-out) and judged: the run ended there, not at the old 35 s
    assert _times(tmp_path / "grinder_feed.csv")[-1] <= 31.025 + 1.0
    assert main(["run", "grinder_feed", "--tolerance", "-1", "--out", str(tmp_path)]) == EXIT_REFUSED


def test_a_sweep_with_a_bad_variant_says_so_and_exits_3_with_set_shared(project, tmp_path, capsys):
    """x_axis.counts_per_rev 512: the encoder's 0.02 mm steps make the size 0.66 mm too deep; --set feed.T1 (the
    spark-out) reaches both variants: each cycle ends 1.45 s earlier than the system's 32.475 s."""
    out = tmp_path / "sw"
    rc = main(["sweep", "grinder_feed", "--vary", "x_axis.counts_per_rev=1048576,512", "--set", "feed.T1=0.05",
               "--workers", "0", "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == EXIT_PART_REJECTED, text
    with open(out / "summary.csv", newline="") as f:
        rows = {r["x_axis.counts_per_rev"]: r for r in csv.DictReader(f)}
    fine, coarse = rows["1048576"], rows["512"]
    assert fine["status"] == "ok" and fine["error"] == ""
    assert float(fine["cycle_time_s"]) == pytest.approx(32.475 - 1.45, abs=1e-6)
    assert coarse["status"] == "out_of_tolerance"
    assert coarse["error"].startswith("part out of tolerance 0.01 mm: gouge")
    assert float(coarse["max_gouge_mm"]) > 0.01
    assert "1 ok, 0 crashed, 1 out_of_tolerance" in text
    # each variant ran to its end, not to the old 35 s
    assert float(fine["sim_time"]) <= 31.025 + 1.0
    assert main(["plot", str(out / "summary.csv")]) == EXIT_OK
    # --set of a varied variable is refused
    assert main(["sweep", "grinder_feed", "--vary", "feed.T1=1,2", "--set", "feed.T1=0.05", "--workers", "0",
                 "--out", str(tmp_path / "both")]) == EXIT_REFUSED


def test_an_unfinished_variant_makes_the_sweep_exit_4(project, tmp_path, capsys):
    rc = main(["sweep", "grinder_feed", "--vary", "panel.override=1", "--stop-time", "2", "--workers", "0",
               "--out", str(tmp_path / "sw")])
    assert rc == EXIT_NOT_FINISHED
    assert "unfinished: panel.override=1: cycle not finished by t = 2 s" in capsys.readouterr().out
