"""A sweep's row says whether the variant's cycle finished, and ``ncfmu sweep`` exits 4 when any did not.

Statuses: ``ok`` (the run reached its stop time and every cycle of the system's report finished),
``unfinished`` (it ran, but a cycle was still running or never started at the stop time: the error column says
``cycle not finished by t = <stop> s``), ``failed``, ``timeout`` (and ``crashed``, ``out_of_tolerance``:
tests/cli/test_run_end.py). Exit status 0 only when every variant is ``ok``, else 4 (3 for a part rejected).
"""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from ncfmu.cli import main
from ncfmu.exitcodes import EXIT_NOT_FINISHED

pytestmark = pytest.mark.slow        # whole systems in closed loop: not in the fast subset

#: grinder_feed's cycle ends at 32.475 s; at override 0.5 every feed word takes twice as long (63.285 s).
CYCLE_END = 32.475


def _rows(out: Path) -> dict[str, dict[str, str]]:
    with open(out / "summary.csv", newline="") as f:
        return {r["panel.override"]: r for r in csv.DictReader(f)}


def test_a_variant_whose_cycle_does_not_finish_is_unfinished_and_the_sweep_exits_4(project, tmp_path, capsys):
    out = tmp_path / "sw"
    rc = main(["sweep", "grinder_feed", "--vary", "panel.override=1,0.5", "--stop-time", "40", "--workers", "0",
               "--out", str(out)])
    assert rc == EXIT_NOT_FINISHED
    rows = _rows(out)
    assert rows["1"]["status"] == "ok" and rows["1"]["error"] == ""
    assert float(rows["1"]["cycle_time_s"]) == pytest.approx(CYCLE_END, abs=1e-9)
    slow = rows["0.5"]
    assert slow["status"] == "unfinished"
    assert slow["error"] == "cycle not finished by t = 40 s"
    assert slow["cycle_time_s"] == "nan"
    # it ran to the stop time: its metrics and trajectory are there (at 40 s the fine feed is still running)
    assert 4.2 < float(slow["deepest_x_mm"]) < 4.3
    assert len((out / "variants" / f"{slow['key']}.csv").read_text().splitlines()) == 40_001 + 1
    text = capsys.readouterr().out
    assert "2 variants, 1 ok, 0 crashed, 0 out_of_tolerance, 1 unfinished, 0 failed, 0 timeout" in text
    assert "unfinished: panel.override=0.5: cycle not finished by t = 40 s" in text


def test_a_sweep_whose_variants_all_finish_exits_0(project, tmp_path):
    out = tmp_path / "sw"
    assert main(["sweep", "grinder_feed", "--vary", "panel.override=1,1.2", "--stop-time", "35", "--workers", "0",
                 "--out", str(out)]) == 0
    rows = _rows(out)
    assert [r["status"] for r in rows.values()] == ["ok", "ok"]
    # faster at 1.2: every feed word's D/F + F/a is shorter (the 1.5 s spark-out is not)
    assert float(rows["1.2"]["cycle_time_s"]) < float(rows["1"]["cycle_time_s"]) == pytest.approx(CYCLE_END)


def test_a_failed_or_timed_out_variant_makes_the_sweep_exit_4(project, tmp_path, capsys):
    assert main(["sweep", "grinder_feed", "--vary", "feed.D3=4,-1", "--stop-time", "35", "--workers", "0",
                 "--out", str(tmp_path / "failed")]) == EXIT_NOT_FINISHED
    assert "1 ok, 0 crashed, 0 out_of_tolerance, 0 unfinished, 1 failed" in capsys.readouterr().out
    # a microsecond of wall time for a 35 s run: over it
    assert main(["sweep", "grinder_feed", "--vary", "feed.D3=4", "--stop-time", "35", "--workers", "0",
                 "--timeout", "1e-6", "--out", str(tmp_path / "timeout")]) == EXIT_NOT_FINISHED
    assert "0 ok, 0 crashed, 0 out_of_tolerance, 0 unfinished, 0 failed, 1 timeout" in capsys.readouterr().out


def test_an_unfinished_variant_is_done_for_a_resumed_sweep(project, tmp_path):
    from ncfmu.batch import sweep
    first = sweep("grinder_feed", {"panel.override": [0.5]}, tmp_path, workers=0, stop_time=3.0, progress=False)
    assert [r["status"] for r in first] == ["unfinished"]
    calls: list[dict] = []
    again = sweep("grinder_feed", {"panel.override": [0.5]}, tmp_path, workers=0, stop_time=3.0, progress=False,
                  on_done=calls.append)
    assert calls == [] and again[0]["status"] == "unfinished"
    assert again[0]["error"] == "cycle not finished by t = 3 s"
