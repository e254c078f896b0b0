"""Where a system may load code from: an FMU only from inside its .ssp archive (or an unpacked .ssd's folder).

The evil FMU is a real one: a copy of the built OperatorPanel whose model script also writes a marker file
when it is imported. An .ssp whose ``panel`` points at it by ``..``, an absolute path, a ``file:`` URL or a
symbolic link in the archive must be refused naming the component -- the marker proves the copy never ran.
"""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from conftest import ROOT

from ncfmu.cosim.ssp import SSD_NAME, fmu_path, read_ssd, read_ssp
from ncfmu.errors import SystemDefinitionError
from ncfmu.project import OpenSystem

PANEL_SOURCE = 'source="resources/OperatorPanel.fmu"'
NCFMU = str(Path(sys.executable).parent / "ncfmu")


def evil_fmu(folder: Path) -> tuple[Path, Path]:
    """A copy of the built OperatorPanel whose model module writes ``marker`` when imported."""
    marker = folder / "evil_ran.txt"
    evil = folder / "some" / "where" / "evil.fmu"
    evil.parent.mkdir(parents=True)
    with zipfile.ZipFile(ROOT / "fmus" / "OperatorPanel.fmu") as zin, zipfile.ZipFile(evil, "w") as zout:
        scripts = [n for n in zin.namelist() if n.startswith("resources/OperatorPanel_") and n.endswith(".py")]
        assert len(scripts) == 1, zin.namelist()
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == scripts[0]:
                data = f"open({str(marker)!r}, 'w').write('loaded')\n".encode() + data
            zout.writestr(item, data)
    return evil, marker


def ssp_with_panel(tmp_path: Path, source: str, symlink_to: str | None = None) -> Path:
    """lathe_taper.ssp with the panel's source replaced and the archive's own OperatorPanel.fmu removed (or,
    with ``symlink_to``, replaced by a symbolic link entry pointing there)."""
    out = tmp_path / "edited.ssp"
    with zipfile.ZipFile(ROOT / "ssp" / "lathe_taper.ssp") as zin, zipfile.ZipFile(out, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == SSD_NAME:
                text = data.decode()
                assert PANEL_SOURCE in text
                data = text.replace(PANEL_SOURCE, f'source="{source}"').encode()
            elif item.filename == "resources/OperatorPanel.fmu":
                continue
            zout.writestr(item, data)
        if symlink_to is not None:
            link = zipfile.ZipInfo("resources/OperatorPanel.fmu")
            link.create_system = 3                                  # unix: the mode bits below count
            link.external_attr = (stat.S_IFLNK | 0o777) << 16
            zout.writestr(link, symlink_to)
    return out


def sources(evil: Path) -> dict[str, str]:
    return {
        "dot-dot": "resources/" + "../" * 40 + str(evil).lstrip("/"),   # enough ../ to reach / from any temp dir
        "absolute": str(evil),
        "file-url": evil.as_uri(),
        "other-scheme": "https://example.com/evil.fmu",
        "folder": "resources/some/where/evil.fmu",
        "backslash": "resources\\..\\..\\evil.fmu",
    }


@pytest.mark.parametrize("kind", ["dot-dot", "absolute", "file-url", "other-scheme", "folder", "backslash"])
def test_a_source_outside_the_archive_is_refused_naming_the_component(project, tmp_path, kind):
    evil, marker = evil_fmu(tmp_path)
    archive = ssp_with_panel(tmp_path, sources(evil)[kind])
    with pytest.raises(SystemDefinitionError, match="component panel: source .*inside the archive") as err:
        read_ssp(archive)
    assert "\n" not in str(err.value)
    with pytest.raises(SystemDefinitionError, match="component panel"):
        OpenSystem(archive)
    assert not marker.exists()


def test_a_symbolic_link_in_the_archive_is_refused_naming_the_component(project, tmp_path):
    evil, marker = evil_fmu(tmp_path)
    archive = ssp_with_panel(tmp_path, "resources/OperatorPanel.fmu", symlink_to=str(evil))
    with pytest.raises(SystemDefinitionError, match="component panel: resources/OperatorPanel.fmu is a symbolic "
                                                    "link"):
        OpenSystem(archive)
    assert not marker.exists()


def test_any_symbolic_link_entry_is_refused_by_the_extraction(project, tmp_path):
    """Not only an FMU: a link among the parameter files is refused too (the entry is named)."""
    from ncfmu.cosim.fmu import safe_extract
    archive = tmp_path / "links.ssp"
    shutil.copyfile(ROOT / "ssp" / "lathe_taper.ssp", archive)
    with zipfile.ZipFile(archive, "a") as z:
        link = zipfile.ZipInfo("resources/extra.ssv")
        link.create_system = 3
        link.external_attr = (stat.S_IFLNK | 0o777) << 16
        z.writestr(link, "/etc/passwd")
    with pytest.raises(SystemDefinitionError, match="entry 'resources/extra.ssv' is a symbolic link"):
        safe_extract(archive, tmp_path / "x")
    assert not (tmp_path / "x" / "resources" / "extra.ssv").exists()


def test_an_unpacked_ssd_loads_fmus_only_from_inside_its_folder(project, tmp_path):
    """In a system folder a link to an FMU elsewhere in the folder is fine; one that leads out is refused."""
    evil, _ = evil_fmu(tmp_path)
    folder = tmp_path / "system"
    shutil.copytree(ROOT / "ssp" / "lathe_taper", folder)
    (folder / "fmus").mkdir()
    shutil.copyfile(ROOT / "fmus" / "OperatorPanel.fmu", folder / "fmus" / "OperatorPanel.fmu")
    system = read_ssd(folder / SSD_NAME)
    panel = system.component("panel")
    link = folder / "resources" / "OperatorPanel.fmu"
    os.symlink(Path("..") / "fmus" / "OperatorPanel.fmu", link)
    assert fmu_path(folder, panel) == (folder / "fmus" / "OperatorPanel.fmu").resolve()
    link.unlink()
    os.symlink(evil, link)
    with pytest.raises(SystemDefinitionError, match="component panel: resources/OperatorPanel.fmu leads outside"):
        fmu_path(folder, panel)
    link.unlink()
    with pytest.raises(SystemDefinitionError, match="component panel: FMU not found: resources/OperatorPanel.fmu"):
        fmu_path(folder, panel)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["dot-dot", "absolute", "file-url", "symlink"])
def test_ncfmu_run_refuses_the_evil_ssp_and_never_runs_its_fmu(project, tmp_path, kind):
    """Through the console script, in its own process: rc 2, one line naming the component, no marker."""
    evil, marker = evil_fmu(tmp_path)
    if kind == "symlink":
        archive = ssp_with_panel(tmp_path, "resources/OperatorPanel.fmu", symlink_to=str(evil))
    else:
        archive = ssp_with_panel(tmp_path, sources(evil)[kind])
    proc = subprocess.run([NCFMU, "run", str(archive), "--stop-time", "0.05", "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, (proc.returncode, proc.stdout[-800:], proc.stderr[-1500:])
    assert len(lines) == 1 and lines[0].startswith("ncfmu run: ") and "component panel" in lines[0], lines
    assert not marker.exists()


@pytest.mark.slow
def test_the_evil_copy_is_a_working_fmu(project, tmp_path):
    """The check above means something only if the copy would run: loaded directly, it writes its marker."""
    code = ("import sys; from ncfmu.cosim.fmu import FmuSlave, UnpackedFmu; "
            "s = FmuSlave(UnpackedFmu(sys.argv[1]), 'p'); s.initialize(0.0, 1.0); s.terminate()")
    evil, marker = evil_fmu(tmp_path)
    proc = subprocess.run([sys.executable, "-c", code, str(evil)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-1500:]
    assert marker.read_text() == "loaded"


def _ssd_with(text_edit) -> str:
    return text_edit((ROOT / "ssp" / "lathe_taper" / SSD_NAME).read_text())


def test_a_duplicate_component_name_is_named_as_such(project, tmp_path):
    folder = tmp_path / "dup"
    shutil.copytree(ROOT / "ssp" / "lathe_taper", folder)
    ssd = folder / SSD_NAME
    text = ssd.read_text()
    x_axis = 'name="x_axis" type="application/x-fmu-sharedlibrary"'
    assert x_axis in text
    ssd.write_text(text.replace(x_axis, 'name="z_axis" type="application/x-fmu-sharedlibrary"'))
    with pytest.raises(SystemDefinitionError, match=r"component name 'z_axis' is used twice") as err:
        read_ssd(ssd)
    assert "no component" not in str(err.value)
