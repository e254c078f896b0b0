"""Ordinary mistakes get one line and exit status 2, never a traceback, a silent rounding or an ignored value
(the reproductions, each through the CLI in its own process)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from conftest import ROOT

pytestmark = pytest.mark.slow        # a process per case (the console script): not in the fast subset


def ncfmu(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ncfmu.cli", *args], capture_output=True, text=True, timeout=300,
                          cwd=cwd)


def assert_refused(proc: subprocess.CompletedProcess, *says: str) -> None:
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-1500:])
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-1500:]
    for text in says:
        assert text in lines[0], lines[0]


@pytest.mark.parametrize("value, says", [
    ("2.9", "seq.block[1].N = 2.9: must be a whole number"),
    ("4294967298", "seq.block[1].N = 4294967298: must be a whole number in -2147483648..2147483647"),
    ("abc", "seq.block[1].N = 'abc': must be a whole number"),
])
def test_an_integer_is_never_rounded_or_wrapped(project, value, says):
    assert_refused(ncfmu("run", "lathe_taper", "--stop-time", "0.01", "--set", f"seq.block[1].N={value}"), says)


def test_a_real_must_be_a_number(project):
    assert_refused(ncfmu("run", "lathe_taper", "--stop-time", "0.01", "--set", "seq.block[1].Xd=abc"),
                   "seq.block[1].Xd = 'abc': must be a number")


def test_a_value_set_on_a_connected_input_is_refused(project):
    assert_refused(ncfmu("run", "mill_contour", "--stop-time", "0.01", "--set", "contour.feed_override=0.5"),
                   "contour.feed_override", "driven by the connection panel.feed_override -> contour.feed_override")


def test_a_stop_time_shorter_than_one_step_is_refused(project):
    assert_refused(ncfmu("run", "lathe_taper", "--step", "7", "--stop-time", "2"),
                   "stop time 2", "shorter than one step")


def test_input_and_branch_at_together_are_refused(project, tmp_path):
    csv = tmp_path / "in.csv"
    csv.write_text("time,panel.feed_override\n0,1.0\n")
    assert_refused(ncfmu("run", "grinder_feed", "--input", str(csv), "--branch-at", "1", "--branch-set",
                         "panel.emergency_at=2,3"), "--input", "--branch-at")


@pytest.mark.parametrize("text, says", [
    ("", "empty"),
    ("time,contour.feed_override\n", "no rows"),
    ("time,contour.feed_override,contour.feed_override\n0,1,1\n", "column 'contour.feed_override' twice"),
    ("time,contour.feed_override\n0,1\n1\n", "line 3"),
    ("time,contour.feed_override\n0,fast\n", "line 2"),
    ("time,contour.feed_override\nnan,1\n", "time must be finite"),
])
def test_a_bad_input_csv_is_one_line(project, tmp_path, text, says):
    csv = tmp_path / "in.csv"
    csv.write_text(text)
    assert_refused(ncfmu("run", "mill_contour", "--stop-time", "0.01", "--input", str(csv)), str(csv), says)


def _ssp_with(tmp_path: Path, edit) -> Path:
    src = ROOT / "ssp" / "lathe_taper.ssp"
    out = tmp_path / "edited.ssp"
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(out, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "SystemStructure.ssd":
                data = edit(data.decode()).encode()
            zout.writestr(item, data)
    return out


@pytest.mark.parametrize("edit, says", [
    (lambda t: t.replace('stopTime="50.0"', 'stopTime="abc"'), "stopTime"),
    (lambda t: t.replace('stopTime="50.0"', 'stopTime="1e9"'), "1e+09"),
    (lambda t: t.replace("<ssd:Elements>", "<ssd:Nothing>").replace("</ssd:Elements>", "</ssd:Nothing>"),
     "ssd:Elements"),
])
def test_a_malformed_ssp_is_one_line(project, tmp_path, edit, says):
    archive = _ssp_with(tmp_path, edit)
    assert_refused(ncfmu("run", str(archive)), says)


@pytest.mark.parametrize("content", [b"", b"this is not a zip archive"])
def test_an_ssp_that_is_not_an_archive_is_one_line(project, tmp_path, content):
    archive = tmp_path / "broken.ssp"
    archive.write_bytes(content)
    assert_refused(ncfmu("run", str(archive)), str(archive), "not an SSP archive")


def test_a_zip_bomb_is_not_extracted(project, tmp_path):
    archive = tmp_path / "bomb.ssp"
    shutil.copyfile(ROOT / "ssp" / "lathe_taper.ssp", archive)
    with zipfile.ZipFile(archive, "a", zipfile.ZIP_DEFLATED) as z:
        with z.open("resources/padding.bin", "w", force_zip64=True) as f:
            block = bytes(1 << 20)
            for _ in range(3 * 1024):                              # 3 GiB of zeros, a few MB packed
                f.write(block)
    assert archive.stat().st_size < 50 * 2 ** 20
    assert_refused(ncfmu("run", str(archive), "--stop-time", "0.01"), "unpacks to more than")
