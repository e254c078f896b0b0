"""``ncfmu vars SYSTEM``: every parameter and input of a system, with what one needs to set it."""

from __future__ import annotations

import re

import pytest

from ncfmu.cli import main
from ncfmu.systems import MODELS, SYSTEMS, get_system


def _listing(capsys, *argv: str) -> dict[str, list[str]]:
    """NAME -> the row's cells (split on runs of 2+ spaces), from ``ncfmu vars``'s table."""
    assert main(["vars", *argv]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split()[:2] == ["NAME", "KIND"]
    rows = {}
    for line in lines[2:]:
        if line.startswith("    start: "):
            continue
        cells = re.split(r" {2,}", line)
        rows[cells[0]] = cells
    return rows


@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_every_parameter_and_input_of_every_instance_is_listed(capsys, name):
    rows = _listing(capsys, name)
    system = get_system(name)
    # each instance's parameters and inputs, then its outputs
    expected = [f"{c.name}.{p.name}" for c in system.components
                for causalities in (("parameter", "input"), ("output",))
                for p in MODELS[c.model].PORTS if p.causality in causalities]
    assert list(rows) == expected
    # inputs say what drives them, outputs what they feed: exactly the system's connections
    drivers = {f"{c.end_element}.{c.end_connector}": f"{c.start_element}.{c.start_connector}"
               for c in system.connections}
    feeds: dict[str, list[str]] = {}
    for c in system.connections:
        feeds.setdefault(f"{c.start_element}.{c.start_connector}", []).append(f"{c.end_element}.{c.end_connector}")
    for qualified, cells in rows.items():
        kind, driven = cells[1], cells[-2]
        if kind == "output":
            assert driven == (f"feeds {', '.join(feeds[qualified])}" if qualified in feeds else "-"), qualified
            continue
        assert driven == (drivers[qualified] if qualified in drivers else "-"), qualified
        if kind != "input":
            assert qualified not in drivers


def test_rows_carry_the_systems_start_value_unit_rule_and_variability(capsys):
    rows = _listing(capsys, "grinder_feed")
    # name, kind, type, unit, start, rule, driven by, description
    assert rows["panel.override"] == ["panel.override", "parameter, tunable", "Real", "1", "1", "must be in [0, 1.5]",
                                      "-", "feed override dial"]
    assert rows["feed.D3"][1:6] == ["parameter, fixed", "Real", "mm", "4", "must be >= 0"]     # the system's, not 0
    assert rows["feed.F2"][4] == "0.005"
    assert rows["x_axis.Kv"][1:6] == ["parameter, fixed", "Real", "1/s", "30", "must be in (0, 10000]"]
    assert rows["panel.pulse"][1] == "parameter, fixed" and rows["panel.pulse"][5] == "must be > 0"
    # Integer and Boolean ports have no unit column text: the cells shift left by one
    assert rows["feed.feed_hold"][:5] == ["feed.feed_hold", "input", "Boolean", "false", "true or false"]
    assert rows["feed.feed_hold"][5] == "panel.feed_hold"
    assert rows["feed.feed_override"][1:7] == ["input", "Real", "1", "1", "must be in [0, 1.5]", "panel.feed_override"]


def test_a_long_start_value_is_written_in_full_below_its_row(capsys):
    from ncfmu.systems.grinder import SEED_PROGRAM
    assert main(["vars", "grinder_feed", "--instance", "feed"]) == 0
    out = capsys.readouterr().out.splitlines()
    at = next(i for i, line in enumerate(out) if line.startswith("feed.program "))
    assert "(below)" in out[at] and out[at + 1] == f"    start: {SEED_PROGRAM}"
    assert all(line.startswith(("feed.", "    start: ")) for line in out[2:])


def test_an_ssp_path_lists_the_same_as_its_name(project, capsys):
    by_name = _listing(capsys, "lathe_roughing")
    by_path = _listing(capsys, str(project["ssp"][[p.stem for p in project["ssp"]].index("lathe_roughing")]))
    assert by_path == by_name


def test_a_model_ncfmu_does_not_define_is_listed_from_its_model_description(project, monkeypatch):
    """The path an .ssp of the user's takes: the FMU's own modelDescription (here the ServoAxis's, read as if
    ncfmu did not know the model) gives the same rows as the ports."""
    import zipfile

    from ncfmu.systems import settable as mod
    fmu = next(p for p in project["fmus"] if p.stem == "ServoAxis")
    system = get_system("mill_contour")
    known = [r for r in mod.settable(system) if r.name.startswith("x_axis.")]
    monkeypatch.setattr(mod, "MODELS", {k: v for k, v in MODELS.items() if k != "ServoAxis"})
    assert [r for r in mod.settable(system) if r.name.startswith("x_axis.")] == []      # left out without it
    with zipfile.ZipFile(fmu) as z:
        md = z.read("modelDescription.xml")
    read = [r for r in mod.settable(system, lambda model: md) if r.name.startswith("x_axis.")]
    assert [(r.name, r.kind, r.type, r.unit, r.driven_by) for r in read] == \
           [(r.name, r.kind, r.type, r.unit, r.driven_by) for r in known]
    assert [float(r.start) if r.type == "Real" else r.start for r in read] == \
           [float(r.start) if r.type == "Real" else r.start for r in known]
    # its outputs too, from the modelDescription: unit, description and what they feed, as from the ports
    monkeypatch.setattr(mod, "MODELS", MODELS)
    known_out = [r for r in mod.settable(system, outputs=True) if r.name.startswith("x_axis.") and r.kind == "output"]
    monkeypatch.setattr(mod, "MODELS", {k: v for k, v in MODELS.items() if k != "ServoAxis"})
    read_out = [r for r in mod.settable(system, lambda model: md, outputs=True)
                if r.name.startswith("x_axis.") and r.kind == "output"]
    assert read_out == known_out and len(known_out) == 6


def test_vars_is_found_from_the_top_level_help(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    assert re.search(r"^\s+vars\s+list every parameter and input of a system", capsys.readouterr().out, re.M)


def test_a_bad_system_or_instance_is_one_line_and_status_2(capsys):
    assert main(["vars", "no_such_system"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ncfmu vars: unknown system 'no_such_system'") and err.count("\n") == 1
    assert main(["vars", "lathe_taper", "--instance", "feed"]) == 2
    assert capsys.readouterr().err == ("ncfmu vars: --instance 'feed': lathe_taper has no such instance (instances: "
                                       "panel, seq, limiter, x_axis, z_axis)\n")


def _foreign_ssp(tmp_path, fmus, fmu_bytes: bytes):
    """An .ssp of the user's: a ServoAxis-driven instance of a model ncfmu does not define ("Foreign")."""
    from ncfmu.cosim.ssp import Component, Connection, System, pack, write_system
    from ncfmu.systems.compose import component
    (tmp_path / "fmus").mkdir()
    (tmp_path / "fmus" / "Foreign.fmu").write_bytes(fmu_bytes)
    (tmp_path / "fmus" / "ServoAxis.fmu").write_bytes(fmus["ServoAxis"].read_bytes())
    system = System("mine", [Component("ext", "Foreign", {"Kv": 20.0}), component("y", "ServoAxis")],
                    [Connection("y", "pos", "ext", "pos_cmd")], stop_time=1.0)
    return pack(write_system(system, tmp_path / "systems"), tmp_path / "fmus", tmp_path / "mine.ssp")


def test_an_ssp_with_a_model_of_another_make_lists_it_from_its_fmu(project, fmus, capsys, tmp_path):
    archive = _foreign_ssp(tmp_path, fmus, fmus["ServoAxis"].read_bytes())     # another model, same interface
    rows = _listing(capsys, str(archive))
    assert rows["ext.Kv"][1:5] == ["parameter, fixed", "Real", "1/s", "20"]     # the archive's .ssv value
    assert rows["ext.pos_cmd"][1] == "input" and rows["ext.pos_cmd"][-2] == "y.pos"
    assert rows["ext.vel_ff"][-2] == "-" and "y.Kv" in rows


def test_an_ssp_whose_foreign_fmu_is_broken_is_one_line(project, fmus, capsys, tmp_path):
    archive = _foreign_ssp(tmp_path, fmus, b"not a zip")
    assert main(["vars", str(archive)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"ncfmu vars: {archive}: resources/Foreign.fmu has no readable modelDescription.xml")
    assert err.count("\n") == 1


def test_outputs_are_listed_with_unit_description_and_what_they_feed(capsys):
    """Outputs are what --record takes and an OPC UA client reads: listed after each instance's parameters and
    inputs, with unit and description (the CSV header was the only list)."""
    rows = _listing(capsys, "grinder_feed")
    assert rows["x_axis.pos"][1:] == ["output", "Real", "mm", "-", "-", "feeds feed.x_pos", "actual position (encoder)"]
    assert rows["x_axis.torque"][1:] == ["output", "Real", "N.m", "-", "-", "-", "motor torque"]
    assert rows["feed.m_active"][1] == "output" and rows["feed.m_active"][-2] == "feeds panel.m_active"
    assert main(["vars", "grinder_feed"]) == 0
    head = capsys.readouterr().out.splitlines()[0]
    n_out = sum(p.causality == "output" for c in get_system("grinder_feed").components for p in MODELS[c.model].PORTS)
    assert re.match(rf"grinder_feed: \d+ parameters and inputs, {n_out} outputs\.", head), head


def test_table_rows_beyond_their_count_are_marked_unused(capsys):
    """lathe_taper's limiter reads region[1..2] (n_regions = 2): region[3..32] hold padding (1000002, ...) and are
    marked unused with why; the counted ones are not."""
    rows = _listing(capsys, "lathe_taper", "--instance", "limiter")
    assert rows["limiter.region[2].ref_max"][1] == "parameter, fixed"
    assert rows["limiter.region[3].ref_max"][1] == "parameter, fixed, unused"
    assert rows["limiter.region[3].ref_max"][-1].startswith("unused: reads region[1..2] only (n_regions = 2); ")
    unused = [name for name, cells in rows.items() if cells[1].endswith(", unused")]
    assert len(unused) == 3 * 30 and all(int(re.search(r"\[(\d+)\]", n)[1]) > 2 for n in unused)
    # the grinder's program names D1..D5, F1, F2, F7, T1: the other settings are unused too
    feed = _listing(capsys, "grinder_feed", "--instance", "feed")
    assert feed["feed.D6"][1] == "parameter, fixed, unused" and feed["feed.D3"][1] == "parameter, fixed"
