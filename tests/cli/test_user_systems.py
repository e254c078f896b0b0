"""A user's system on the command line: a bare .fmu, an .ssd with its folder, an unpacked folder; --replace and --map
on any system; ``ncfmu pack``. Through the foreign FMUs of tests/foreign/."""

from __future__ import annotations

import re
import shutil
import zipfile

import numpy as np
import pytest
from foreign_fmus import packed

from ncfmu.cli import main
from ncfmu.cosim.result import Result
from ncfmu.cosim.ssp import Component, Connection, System, read_ssp


def test_replace_on_lathe_taper_with_a_foreign_axis_gives_the_full_summary_and_a_plot(foreign, project, tmp_path,
                                                                                      capsys):
    out = tmp_path / "out"
    assert main(["run", "lathe_taper", "--replace", f"x_axis={foreign['PlantAxisMetre']}", "--out", str(out),
                 "--plot"]) == 0
    text = capsys.readouterr().out
    assert "  cuts (SC2): 4" in text and re.search(r"cycle done: 4\d\.\d+ s; tool at X 30\.0000, Z 2\.0000 mm; "
                                                     r"alarm: no", text)
    assert "  area limiter: no violation" in text
    # the plant records in m, the report reads mm: the cuts start 0.5 mm apart from 28.5 mm, the error in um
    assert re.search(r"X at the start of each cut \[mm\]: 28\.49\d+, 27\.99\d+, 27\.49\d+, 26\.99\d+", text)
    largest = float(re.search(r"  x_axis: max \|following error\| (\d+\.\d+) um", text).group(1))
    assert 1.0 < largest < 100.0
    run = Result.from_csv(out / "lathe_taper.csv")                  # the CSV keeps the FMU's own units
    assert run["x_axis.pos"][0] == pytest.approx(0.030)             # pos_start 30 mm, applied in the plant's metres
    assert np.abs(run["x_axis.following_error"]).max() * 1e6 == pytest.approx(largest, abs=0.01)
    assert (out / "lathe_taper.png").stat().st_size > 10_000


def test_replace_refuses_a_connection_the_new_fmu_cannot_take_and_map_renames(foreign, project, tmp_path, capsys):
    assert main(["run", "lathe_taper", "--replace", f"x_axis={foreign['Feedthrough']}", "--out",
                 str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "the connection limiter.lim_cmd -> x_axis.pos_cmd needs x_axis.pos_cmd, which Feedthrough does not have " \
           "(map it: --map x_axis.THEIRS=pos_cmd)" in err
    assert main(["vars", "lathe_taper", "--replace", f"nope={foreign['PlantAxis']}"]) == 2
    assert "has no instance 'nope'" in capsys.readouterr().err
    # --map: the plant's names for the old connectors
    src = tmp_path / "renamed"
    archive = packed(System("pair", [Component("count", "Countdown", {"end_at": 30.0}),
                                     Component("feed", "Feedthrough")],
                            [Connection("count", "counter", "feed", "int_in")], 2.0, 0.01), foreign, src)
    assert main(["run", str(archive), "--replace", f"feed={foreign['Feedthrough3']}", "--out", str(tmp_path / "o")]) \
        == 0
    capsys.readouterr()
    assert main(["run", str(archive), "--replace", f"count={foreign['Feedthrough']}", "--map",
                 "count.int_out=counter", "--out", str(tmp_path / "o2")]) == 0


def test_a_bare_fmu_an_ssd_folder_and_an_unpacked_folder_run(foreign, project, tmp_path, capsys):
    assert main(["run", str(foreign["Countdown"]), "--stop-time", "3", "--out", str(tmp_path / "a")]) == 0
    assert "system Countdown: simulated 3.000 s" in capsys.readouterr().out
    archive = packed(System("pair", [Component("count", "Countdown", {"end_at": 30.0}),
                                     Component("feed", "Feedthrough", {"gain": 2.0})],
                            [Connection("count", "counter", "feed", "int_in")], 2.0, 0.01), foreign, tmp_path / "p")
    folder = tmp_path / "unpacked"
    with zipfile.ZipFile(archive) as z:
        z.extractall(folder)
    assert main(["run", str(folder), "--out", str(tmp_path / "b")]) == 0
    assert "system pair: simulated 2.000 s" in capsys.readouterr().out
    shutil.move(folder / "SystemStructure.ssd", folder / "mine.ssd")
    assert main(["vars", str(folder / "mine.ssd")]) == 0
    assert re.search(r"feed\.gain\s+parameter, fixed\s+Real\s+2", capsys.readouterr().out)
    assert main(["run", str(tmp_path / "missing.fmu"), "--out", str(tmp_path / "c")]) == 2
    assert "FMU not found" in capsys.readouterr().err


def test_bindings_the_new_fmu_cannot_take_are_named(foreign, project, tmp_path, capsys):
    archive = packed(System("one", [Component("feed", "Feedthrough", {"gain": 2.0, "label": "x"})], [], 1.0, 0.01),
                     foreign, tmp_path / "p")
    assert main(["run", str(archive), "--replace", f"feed={foreign['Countdown']}", "--out", str(tmp_path / "o")]) == 0
    assert "  [warning] --replace feed: parameters not applied (Countdown has no such variable): gain, label" \
        in capsys.readouterr().out
    assert main(["run", str(archive), "--replace", f"feed={foreign['Feedthrough3']}", "--out",
                 str(tmp_path / "o3")]) == 0
    assert "parameters not applied" not in capsys.readouterr().out


def test_pack_writes_a_users_system_as_one_ssp(foreign, project, tmp_path, capsys):
    out = tmp_path / "mine.ssp"
    assert main(["pack", "lathe_taper", "--replace", f"z_axis={foreign['PlantAxis']}", "--output", str(out)]) == 0
    assert f"-> {out}" in capsys.readouterr().out
    system = read_ssp(out)
    assert system.component("z_axis").model == "PlantAxis"
    with zipfile.ZipFile(out) as z:
        assert "resources/PlantAxis.fmu" in z.namelist() and "resources/ServoAxis.fmu" in z.namelist()
    assert main(["run", str(out), "--out", str(tmp_path / "o")]) == 0
    assert "  cuts (SC2): 4" in capsys.readouterr().out
