"""The pytest plugin from a user's test file, sweeps on dask.distributed, plots."""

import csv
import os

import pytest

from ncfmu.batch import sweep
from ncfmu.cli import main
from ncfmu.exitcodes import EXIT_NOT_FINISHED

pytestmark = pytest.mark.slow        # whole systems in closed loop: not in the fast subset

USER_TEST = '''
from ncfmu.systems import GRINDER_TABLE

def test_finish_pass(ncfmu_run, ncfmu_checks):
    r = ncfmu_run("grinder_feed")
    ncfmu_checks.assert_reaches(r, "x_axis.pos", 4.3, band=0.005)
    ncfmu_checks.assert_no_motion(r, "x_axis.pos", (30.6, 31.9))
    ncfmu_checks.assert_alarm(r, "feed.alarm", raised=False)

def test_envelope(ncfmu_run, ncfmu_checks):
    r = ncfmu_run("grinder_envelope")
    ncfmu_checks.assert_inside_envelope(r, "y_axis.pos", "x_axis.pos", GRINDER_TABLE)

def test_a_check_that_must_fail(ncfmu_run, ncfmu_checks):
    ncfmu_checks.assert_reaches(ncfmu_run("grinder_feed"), "x_axis.pos", 9.0, band=0.005)
'''


def test_plugin_fixtures_work_from_a_users_test_file(project, pytester):
    pytester.makepyfile(test_user=USER_TEST)
    result = pytester.runpytest_subprocess("-q", "-p", "no:cacheprovider")
    result.assert_outcomes(passed=2, failed=1)
    result.stdout.fnmatch_lines(["*x_axis.pos never within 0.005 of 9*closest 4.3*"])


def read_summary(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


VARY = {"feed.D3": [4.0, 3.0, -1.0, 3.5]}


def test_sweep_with_a_bad_value_then_rerun_does_no_work(project, tmp_path):
    rows = sweep("grinder_feed", VARY, tmp_path, workers=2, stop_time=3.0, progress=False)
    # 3 s of the 32.5 s cycle: the variants that ran are unfinished, with their metrics
    assert [r["status"] for r in rows] == ["unfinished", "unfinished", "failed", "unfinished"]
    bad = rows[2]
    assert "D3 = -1.0: must be >= 0" in bad["error"]
    # the rapid approach D3 then ~2.5 s of rough grinding at 0.02 mm/s: the deepest point follows D3
    deepest = {float(r["feed.D3"]): float(r["deepest_x_mm"]) for r in read_summary(tmp_path / "summary.csv")
               if r["status"] == "unfinished"}
    assert deepest[4.0] - deepest[3.0] == pytest.approx(1.0, abs=0.003)
    assert deepest[3.5] - deepest[3.0] == pytest.approx(0.5, abs=0.003)
    assert 4.03 < deepest[4.0] < 4.06
    assert len(list((tmp_path / "variants").glob("*.csv"))) == 3
    stamp = os.stat(tmp_path / "summary.csv").st_mtime_ns
    calls = []
    again = sweep("grinder_feed", VARY, tmp_path, workers=2, stop_time=3.0, progress=False, on_done=calls.append)
    assert calls == [] and os.stat(tmp_path / "summary.csv").st_mtime_ns == stamp
    assert [r["status"] for r in again] == ["unfinished", "unfinished", "failed", "unfinished"]


def test_sweep_on_an_existing_cluster_gives_the_same_summary(project, tmp_path):
    from ncfmu.batch import local_cluster
    with local_cluster(2) as cluster:
        # a failed variant (D3 = -1) and unfinished ones (3 s of the cycle): exit status 1 both ways
        assert main(["sweep", "grinder_feed", "--vary", "feed.D3=4.0,3.0,-1,3.5", "--stop-time", "3",
                     "--scheduler", cluster.scheduler_address, "--out", str(tmp_path / "remote")]) == EXIT_NOT_FINISHED
    assert main(["sweep", "grinder_feed", "--vary", "feed.D3=4.0,3.0,-1,3.5", "--stop-time", "3",
                 "--workers", "2", "--out", str(tmp_path / "local")]) == EXIT_NOT_FINISHED
    drop = ("wall_time",)
    remote = [{k: v for k, v in r.items() if k not in drop} for r in read_summary(tmp_path / "remote" / "summary.csv")]
    local = [{k: v for k, v in r.items() if k not in drop} for r in read_summary(tmp_path / "local" / "summary.csv")]
    assert remote == local and len(local) == 4


def test_plots_are_written(project, tmp_path, ncfmu_run):
    from ncfmu.plots import plot_result
    for name in ("lathe_taper", "mill_contour", "grinder_envelope"):
        png = plot_result(ncfmu_run(name), tmp_path / f"{name}.png")
        assert png.stat().st_size > 20_000 and png.read_bytes()[:4] == b"\x89PNG"
    r = ncfmu_run("lathe_taper")
    r.to_csv(tmp_path / "lathe_taper.csv")
    assert main(["plot", str(tmp_path / "lathe_taper.csv"), "--png", str(tmp_path / "again.png")]) == 0
    assert (tmp_path / "again.png").stat().st_size > 20_000


def test_readme_example_test_file_passes(project, pytester):
    from conftest import ROOT
    text = (ROOT / "README.md").read_text()
    section = text.split("## Closed-loop checks in your own pytest files", 1)[1]
    example = section.split("```python", 1)[1].split("```", 1)[0]
    pytester.makepyfile(test_readme=example)
    result = pytester.runpytest_subprocess("-q", "-p", "no:cacheprovider")
    result.assert_outcomes(passed=2)


def test_progress_bar_shows_done_failed_remaining_on_a_terminal():
    import io
    import re

    from ncfmu.batch import Progress

    class Terminal(io.StringIO):
        def isatty(self):
            return True
    term = Terminal()
    bar = Progress(5, stream=term)
    bar.update("ok")
    bar.update("failed")
    bar.update("timeout")
    bar.update("unfinished")
    bar.close()
    last = term.getvalue().rsplit("\r", 1)[-1]
    # 4 of 5 done, elapsed < ETA, and the counts by status (tqdm sorts them by name)
    assert re.search(r"4/5 \[\d\d:\d\d<\d\d:\d\d, .*done=1, failed=1, rejected=0, timeout=1, unfinished=1\]",
                     last), last
    pipe = io.StringIO()                       # not a terminal: silent
    Progress(4, stream=pipe).update("ok")
    assert pipe.getvalue() == ""
