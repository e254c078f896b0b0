"""Hostile inputs to the command line and the SSP reader, as an adversarial user sends them (each reproduced a
defect first): an .ssp that inflates to GBs, a scheduler that accepts and never answers or speaks another
transport, plots of CSVs that are not what their name or --system says, a BOM, an SSP source with './'."""

import json
import socket
import subprocess
import sys
import threading
import zipfile
from pathlib import Path

import pytest
from conftest import ROOT

import ncfmu.cosim.ssp as ssp_module
from ncfmu.errors import SystemDefinitionError

SSP = ROOT / "ssp" / "lathe_taper.ssp"        # built by the session fixture `project`
NCFMU = [str(Path(sys.executable).with_name("ncfmu"))]


def _bomb(path: Path, padding: int) -> Path:
    """lathe_taper.ssp whose SystemStructure.ssd is `padding` spaces and then not XML (compresses ~1000:1)."""
    src = zipfile.ZipFile(SSP)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as out:
        out.writestr("SystemStructure.ssd", b" " * padding + b"<not-xml")
        for n in src.namelist():
            if n != "SystemStructure.ssd":
                out.writestr(n, src.read(n))
    return path


def test_ssp_size_limit_is_checked_before_the_ssd_is_read(project, tmp_path, monkeypatch):
    """OpenSystem now reads the SSD (and .ssv) out of the archive before safe_extract's size check: a 2 MB .ssp
    whose SSD inflates to GBs is read into memory whole (MemoryError traceback / OOM) instead of being refused.
    Here the limit is lowered to 1 MiB and the SSD is 2 MiB of spaces and then garbage: the size refusal must
    come first; on main the XML parse error comes first."""
    from ncfmu.project import OpenSystem
    monkeypatch.setattr(ssp_module, "MAX_UNPACKED", 2 ** 20)
    archive = _bomb(tmp_path / "bomb.ssp", 2 * 2 ** 20)
    with pytest.raises(SystemDefinitionError, match="unpacks to more than"):
        OpenSystem(archive)


@pytest.fixture
def silent_listener():
    """A TCP port that accepts connections and never says a word (a stopped scheduler, a wrong service)."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    held, stop = [], threading.Event()

    def accept():
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                held.append(srv.accept()[0])
            except OSError:
                pass
    threading.Thread(target=accept, daemon=True).start()
    yield srv.getsockname()[1]
    stop.set()
    for c in held:
        c.close()
    srv.close()


@pytest.mark.slow
def test_connect_timeout_bounds_a_scheduler_that_accepts_and_never_answers(silent_listener, tmp_path):
    """--connect-timeout 1: the line must come within a few seconds; on main the command hangs until the peer
    closes the connection (unbounded), then claims 'no dask scheduler answered within 1 s'."""
    try:
        proc = subprocess.run([*NCFMU, "sweep", "lathe_taper", "--vary", "seq.accel=400", "--out", str(tmp_path),
                               "--scheduler", f"tcp://127.0.0.1:{silent_listener}", "--connect-timeout", "1"],
                              capture_output=True, text=True, timeout=30)
    except subprocess.TimeoutExpired:
        pytest.fail("ncfmu sweep --connect-timeout 1 still waiting after 30 s")
    assert proc.returncode == 2 and "no dask scheduler answered" in proc.stderr


@pytest.mark.slow
@pytest.mark.parametrize("address", ["tls://127.0.0.1:1", "ucx://127.0.0.1:1"])
def test_scheduler_file_of_another_transport_is_one_line(address, tmp_path):
    """A TLS (or UCX) scheduler's file: one line and exit 2; on main a TypeError traceback."""
    sched = tmp_path / "scheduler.json"
    sched.write_text(json.dumps({"address": address}))
    proc = subprocess.run([*NCFMU, "sweep", "lathe_taper", "--vary", "seq.accel=400", "--out", str(tmp_path / "o"),
                           "--scheduler-file", str(sched), "--connect-timeout", "1"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr[-400:]
    assert proc.stderr.startswith("ncfmu sweep: --scheduler-file")


@pytest.mark.slow
def test_plot_with_system_that_the_csv_does_not_hold_is_refused(tmp_path):
    """--system lathe_taper on a CSV without any of lathe_taper's columns: main draws empty axes and reports
    success; it should say the CSV holds none of the system's signals (exit 2)."""
    csv = tmp_path / "foreign.csv"
    csv.write_text("time,a\n0,1\n1,2\n")
    proc = subprocess.run([*NCFMU, "plot", str(csv), "--system", "lathe_taper", "--png", str(tmp_path / "x.png")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr


@pytest.mark.slow
@pytest.mark.parametrize("name, png", [("summary.csv", "x.png"), ("foreign.csv", "x.foo")])
def test_plot_foreign_csv_never_a_traceback(tmp_path, name, png):
    """A foreign CSV that happens to be called summary.csv, or --png with a suffix matplotlib cannot write:
    one line, exit 2 (main: ValueError traceback)."""
    csv = tmp_path / name
    csv.write_text("time,a\n0,1\n1,2\n")
    proc = subprocess.run([*NCFMU, "plot", str(csv), "--png", str(tmp_path / png)], capture_output=True, text=True,
                          timeout=120)
    assert "Traceback" not in proc.stderr, proc.stderr[-300:]


def test_result_csv_with_utf8_bom_reads(tmp_path):
    """Excel's 'CSV UTF-8' starts with a BOM: main refuses it ("needs a first column 'time', not '\\ufefftime'")."""
    from ncfmu.cosim.result import Result
    csv = tmp_path / "excel.csv"
    csv.write_bytes(b"\xef\xbb\xbftime,a\r\n0,1\r\n1,2\r\n")
    assert list(Result.from_csv(csv).time) == [0.0, 1.0]


def test_parameter_binding_with_dot_slash_still_reads(project, tmp_path):
    """OpenSystem reads the SSD from the archive now (read_ssp): a ParameterBinding source './resources/seq.ssv'
    (a plain relative URI, read fine from the extracted folder before) is 'not in the archive'."""
    from ncfmu.project import OpenSystem
    z = zipfile.ZipFile(SSP)
    archive = tmp_path / "dot.ssp"
    with zipfile.ZipFile(archive, "w") as out:
        for n in z.namelist():
            data = z.read(n)
            if n == "SystemStructure.ssd":
                data = data.replace(b'source="resources/seq.ssv"', b'source="./resources/seq.ssv"')
            out.writestr(n, data)
    with OpenSystem(archive) as opened:
        assert [c.name for c in opened.system.components][1] == "seq"
