"""Plots a controls engineer puts in a report: the lathe's machine plane without empty space, a sweep summary
of metrics only with unfinished and failed variants visible, the ServoAxis Bode plot over the band that matters
with the design's margins."""

from __future__ import annotations

import numpy as np
import pytest

from ncfmu.exitcodes import EXIT_NOT_FINISHED

pytest.importorskip("matplotlib")     # the plot extra; the test extra installs it (CI runs these)


def _longest_blank_band(png) -> float:
    """The tallest run of all-white pixel rows, as a fraction of the image's height."""
    import matplotlib.image as mpimg
    image = mpimg.imread(str(png))[..., :3]
    blank = (image > 0.99).all(axis=(1, 2))
    best = run = 0
    for row_blank in blank:
        run = run + 1 if row_blank else 0
        best = max(best, run)
    return best / len(blank)


# -- the lathe: the chuck's label stays inside its panel -----------------------------------------------------
@pytest.mark.slow
def test_the_lathe_plot_has_no_empty_band_and_names_the_chuck_inside_its_panel(lathe_taper, tmp_path):
    import matplotlib.pyplot as plt

    from ncfmu.plots import plot_result
    from ncfmu.systems import report_of, run_parameters
    png = plot_result(lathe_taper, tmp_path / "lathe_taper.png")
    # before: the chuck's name drawn at X = 40, above the panel's X 25..32, and tight_layout squeezed the three
    # panels to make room for it: 26 % of the figure's height was blank rows
    assert _longest_blank_band(png) < 0.03
    fig, ax = plt.subplots()
    report_of(lathe_taper).draw_plane(ax, lathe_taper, run_parameters(lathe_taper))
    fig.canvas.draw()
    low, high = ax.get_ylim()
    assert high < 40.0                                       # the chuck's bound is out of this view ...
    labels = {t.get_text(): t for t in ax.texts}
    chuck = labels["chuck: x_axis < 40 forbidden"]           # ... so its name says the bound, inside the panel
    box, frame = chuck.get_window_extent(), ax.get_window_extent()
    assert frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
    plt.close(fig)


# -- the sweep summary ------------------------------------------------------------------------------------
#: A summary as ncfmu.batch writes it: the varied values, status, error, rows, then the metrics.
HEADER = ["key", "panel.override", "feed.D3", "status", "error", "rows", "sim_time", "wall_time", "deepest_x_mm",
          "cycle_time_s", "max_following_error_mm", "alarms"]
ROWS = [
    ["a", "1", "4", "ok", "", "40001", "40.0", "0.5", "4.3", "32.475", "0.0014", "0"],
    ["b", "1.2", "4", "ok", "", "40001", "40.0", "0.5", "4.3", "27.3", "0.0015", "0"],
    ["c", "0.5", "4", "unfinished", "cycle not finished by t = 40 s", "40001", "40.0", "0.5", "4.25", "nan",
     "0.0008", "0"],
    ["d", "0.8", "4", "failed", "feed: D3 = -1.0: must be >= 0", "", "", "0.1", "", "", "", ""],
    ["e", "0.9", "4", "timeout", "over the time allowed", "", "", "0.1", "", "", "", ""],
]


def _sweep_figure():
    from ncfmu.plots import sweep_figure
    return sweep_figure([dict(zip(HEADER, r)) for r in ROWS], "sweep sw")


def test_the_sweep_plot_draws_metrics_only():
    import matplotlib.pyplot as plt
    fig = _sweep_figure()
    assert [ax.get_ylabel() for ax in fig.axes] == ["deepest_x_mm", "cycle_time_s", "max_following_error_mm",
                                                    "alarms"]                         # no rows, no times of the run
    assert fig.axes[0].get_title() == "sweep sw: 2 ok, 1 unfinished, 1 failed, 1 timeout"
    plt.close(fig)


def _legend(ax) -> list[str]:
    return [text.get_text() for text in ax.get_legend().get_texts()]


def test_the_sweep_plot_shows_unfinished_nan_and_failed_variants():
    import matplotlib.pyplot as plt
    fig = _sweep_figure()
    deepest, cycle = fig.axes[0], fig.axes[1]
    lines = {line.get_label(): line for line in cycle.get_lines()}
    # the cycle time of the unfinished variant is nan: an x at its override, not dropped
    nan = lines["no value (nan): cycle not finished"]
    assert list(nan.get_xdata()) == [0.5] and nan.get_marker() == "x"
    # the ok variants are the line; the unfinished one's deepest point (at the stop time) an open marker
    assert sorted(lines["feed.D3=4"].get_xdata()) == [1.0, 1.2]
    open_ = {line.get_label(): line for line in deepest.get_lines()}["unfinished: value at the stop time"]
    assert list(open_.get_xdata()) == [0.5] and list(open_.get_ydata()) == [4.25] and open_.get_mfc() == "none"
    # failed and timed-out variants: a marker each at their override, on every panel
    for ax in fig.axes:
        marks = {line.get_label(): list(line.get_xdata()) for line in ax.get_lines()}
        assert marks["failed, no value: feed.D3=4"] == [0.8] and marks["timeout, no value: feed.D3=4"] == [0.9]
        assert set(_legend(ax)) >= {"feed.D3=4", "failed, no value: feed.D3=4", "timeout, no value: feed.D3=4"}
    plt.close(fig)


def test_plot_sweep_writes_the_png(tmp_path):
    import csv

    from ncfmu.plots import plot_sweep
    summary = tmp_path / "sw" / "summary.csv"
    summary.parent.mkdir()
    with open(summary, "w", newline="") as f:
        csv.writer(f).writerows([HEADER, *ROWS])
    png = plot_sweep(summary, tmp_path / "sw.png")
    assert png.read_bytes()[:4] == b"\x89PNG" and _longest_blank_band(png) < 0.05


def test_a_sweep_of_part_programs_plots_with_numbered_values_and_its_rejected_variants(tmp_path):
    """A program text as a sweep value: numbered on the axis and listed under the panels (as tick labels the
    texts overlapped into one smear); a variant out of tolerance is drawn, marked as rejected."""
    import csv

    import matplotlib.pyplot as plt

    from ncfmu.cli import main
    from ncfmu.plots import sweep_figure
    programs = ["M0: X+D3F7; M1: X+D2F1; M2: X+D5F2; M3: T1; M4: X-D4F7; M5: END",
                "M0: X+D3F7\nM1: X+D2F7; M2: X+D5F2; M3: T1; M4: X-D4F7; M5: END"]
    header = ["key", "feed.program", "status", "error", "rows", "sim_time", "wall_time", "max_gouge_mm"]
    rows = [["a", programs[0], "ok", "", "100", "31.0", "0.5", "0.000003"],
            ["b", programs[1], "out_of_tolerance", "part out of tolerance 0.01 mm: gouge 0.66 mm", "100", "31.0",
             "0.5", "0.66"]]
    fig = sweep_figure([dict(zip(header, r)) for r in rows], "sweep sw")
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["#1", "#2"]
    assert ax.get_xlabel() == "feed.program (values listed below)"
    key = "\n".join(t.get_text() for t in fig.texts)
    assert f"#1: {programs[0]}" in key and "#2: M0: X+D3F7 | M1: X+D2F7" in key     # a program's lines on one
    rejected = {line.get_label(): line for line in ax.get_lines()}["out of tolerance: the part rejected"]
    assert list(rejected.get_xdata()) == [1.0] and list(rejected.get_ydata()) == [0.66]
    assert ax.get_title() == "sweep sw: 1 ok, 1 out_of_tolerance"
    plt.close(fig)
    summary = tmp_path / "summary.csv"
    with open(summary, "w", newline="") as f:
        csv.writer(f).writerows([header, *rows])
    assert main(["plot", str(summary)]) == 0 and (tmp_path / "summary.png").stat().st_size > 10_000


# -- the ServoAxis Bode plot ------------------------------------------------------------------------------
AXES = {"defaults": {}, "stiffer": {"Kv": 60.0, "vel_bandwidth": 800.0, "tau_current": 0.25e-3}}


@pytest.mark.parametrize("which", sorted(AXES))
def test_the_bode_band_and_margins_are_the_designs(which):
    from ncfmu.servo.bode import bode_design
    from ncfmu.servo.model import AxisParameters, design
    p = AxisParameters(**AXES[which])
    d, bode = design(p), bode_design(p)
    low, high = bode.band
    # a decade below the position loop's bandwidth to a decade above the current loop's corner
    assert low == pytest.approx(d.position_bandwidth / 10) and high == pytest.approx(10 / p.tau_current)
    velocity, position = bode.loops
    assert low < d.position_crossover < d.velocity_crossover < high
    assert velocity.phase_margin == pytest.approx(d.velocity_margin) and \
        velocity.gain_crossover == pytest.approx(d.velocity_crossover)
    assert position.phase_margin == pytest.approx(d.position_margin) and \
        position.gain_crossover == pytest.approx(d.position_crossover)
    # the velocity loop (PI, current lag, mechanics) tends to -180 deg but never reaches it: an infinite gain
    # margin, said in words; the position loop (one more integrator) crosses -180 inside the band
    assert velocity.gain_margin == np.inf and np.isnan(velocity.phase_crossover)
    assert velocity.gain_margin_text() == "GM infinite (the phase never reaches -180 deg)"
    assert low < position.phase_crossover < high and 1 < position.gain_margin < np.inf


def test_the_bode_figure_draws_the_band_and_the_margins():
    import matplotlib.pyplot as plt

    from ncfmu.servo.bode import bode_figure
    from ncfmu.servo.model import design
    d = design()
    fig, bode = bode_figure()
    ax_mag, ax_ph = fig.axes
    assert ax_ph.get_xlim() == pytest.approx(bode.band)
    velocity, position = bode.loops
    curves = [line for line in ax_ph.get_lines() if len(line.get_xdata()) > 2]
    mags = [line for line in ax_mag.get_lines() if len(line.get_xdata()) > 2]
    for curve, mag, margins in zip(curves, mags, bode.loops):
        w, phase = np.asarray(curve.get_xdata()), np.asarray(curve.get_ydata())
        # no artefact: in the band every loop's phase lies between -270 and -90 deg, its gain within 150 dB
        assert phase.max() <= -90 + 1e-6 and phase.min() > -270
        assert np.abs(np.asarray(mag.get_ydata())).max() < 150
        # the curve drawn crosses 0 dB where the margin is read, with the phase margin the design says
        assert np.interp(np.log(margins.gain_crossover), np.log(w), phase) == pytest.approx(
            -180 + margins.phase_margin, abs=0.2)
    texts = [t.get_text() for t in ax_ph.texts]
    assert f"PM {d.velocity_margin:.1f}°" in texts and f"PM {d.position_margin:.1f}°" in texts
    assert [t.get_text() for t in ax_mag.texts if t.get_text().startswith("GM")] == \
        [f"GM {20 * np.log10(position.gain_margin):.1f} dB"]
    legend = [t.get_text() for t in ax_mag.get_legend().get_texts()]
    assert legend == [f"velocity_loop: PM {d.velocity_margin:.1f} deg at {d.velocity_crossover:.1f} rad/s; "
                      "GM infinite (the phase never reaches -180 deg)",
                      f"position_loop: PM {d.position_margin:.1f} deg at {d.position_crossover:.1f} rad/s; "
                      f"GM {20 * np.log10(position.gain_margin):.1f} dB at {position.phase_crossover:.0f} rad/s"]
    plt.close(fig)


def test_the_servo_fmu_documentation_carries_the_band_and_margins(fmus):
    import zipfile

    from ncfmu.servo.bode import bode_design
    bode = bode_design()
    with zipfile.ZipFile(fmus["ServoAxis"]) as z:
        page = z.read("documentation/index.html").decode()
        assert z.read("documentation/bode.png")[:4] == b"\x89PNG"
    assert f"from {bode.band[0]:.1f} to {bode.band[1]:.0f} rad/s" in page
    assert "<td>velocity loop: gain margin</td><td>infinite (the phase never reaches -180 deg)</td>" in page
    assert "Gm = inf" not in page and "nan rad/s" not in page


@pytest.mark.parametrize("model", ["AreaLimiter", "ContourInterpolator", "CutSequencer", "OperatorPanel",
                                   "ProgrammableFeed", "ServoAxis"])
def test_fmu_documentation_shows_names_as_code_not_sphinx_markup(fmus, model):
    import re
    import zipfile

    from conftest import ROOT
    with zipfile.ZipFile(fmus[model]) as z:
        page = z.read("documentation/index.html").decode()
    markdown = (ROOT / "docs" / "fmus" / f"{model}.md").read_text()
    for text in (page, markdown):
        assert not re.search(r":(func|meth|class|mod|data|attr):`", text)
        assert "``" not in text.replace("```", "")
    behaviour = page.split("<pre>", 1)[1].split("</pre>", 1)[0]
    assert "<code>" in behaviour


def test_roles_and_literals_render_as_their_names():
    from ncfmu.fmi.documentation import _rendered
    text = "see :func:`~ncfmu.servo.model.servo_axis`, :mod:`.rs274`, :meth:`A.b` and ``x < 1``"
    assert _rendered(text, str, lambda n: f"[{n}]") == \
        "see [ncfmu.servo.model.servo_axis()], [rs274], [A.b()] and [x < 1]"


# -- the offline plot of a run draws what its --plot drew ------------------------------------------------------
def _plane_lines(result) -> dict[str, list[np.ndarray]]:
    """The machine plane's labelled lines of a result's plot (label -> the xy data of each line with it), and
    its constant lines (a stock outline) under their labels: what the plane panel draws, not its pixels."""
    import matplotlib.pyplot as plt

    from ncfmu.systems import report_of, run_parameters
    fig, ax = plt.subplots()
    report_of(result).draw_plane(ax, result, run_parameters(result))
    lines: dict[str, list[np.ndarray]] = {}
    label = ""
    for line in ax.lines:
        label = line.get_label() if not line.get_label().startswith("_") else label   # unlabelled: the one before
        lines.setdefault(label, []).append(np.asarray(line.get_xydata(), dtype=float))
    plt.close(fig)
    return lines


def _plotted_planes(monkeypatch, argv: list[str], status: int = 0) -> list[dict[str, list[np.ndarray]]]:
    """Run ``ncfmu`` with ``argv`` (exiting with ``status``); the plane lines of every result it plotted."""
    from ncfmu import plots
    from ncfmu.cli import main
    planes: list[dict[str, list[np.ndarray]]] = []

    def plotted(result, path, _plot=plots.plot_result):
        planes.append(_plane_lines(result))
        return _plot(result, path)
    monkeypatch.setattr(plots, "plot_result", plotted)
    assert main(argv) == status
    return planes


@pytest.mark.slow
def test_the_offline_plot_of_a_part_program_run_draws_its_profile_as_plot_did(project, tmp_path, monkeypatch,
                                                                                capsys):
    """Before: ``ncfmu plot OUT/lathe_roughing.csv`` read no parameters, so it drew the registers' "stock
    outline X = 29" of the system's parameter set and no profile, while ``--plot`` drew the program's profile."""
    from conftest import ROOT
    program = (ROOT / "docs" / "examples" / "lathe_shaft.ngc").read_text()
    out = tmp_path / "out"
    [live] = _plotted_planes(monkeypatch, ["run", "lathe_roughing", "--stop-time", "1", "--out", str(out),
                                           "--set", f"seq.program={program}", "--plot"], EXIT_NOT_FINISHED)
    assert (out / "lathe_roughing.run.json").is_file()
    [offline] = _plotted_planes(monkeypatch, ["plot", str(out / "lathe_roughing.csv"), "--png",
                                              str(tmp_path / "offline.png")])
    assert offline.keys() == live.keys()
    assert "profile (finished part)" in offline and not any(k.startswith("stock outline") for k in offline)
    for label in ("profile (finished part)", "planned moves"):
        assert len(offline[label]) == len(live[label]) > 0
        for a, b in zip(offline[label], live[label]):
            assert np.array_equal(a, b), label
    # the profile is the program's: the shaft's shoulder at X 27 and its end face at X 14
    profile = np.concatenate(offline["profile (finished part)"])
    assert profile[:, 1].min() == pytest.approx(14.0) and 27.0 in profile[:, 1]
    # the tool path from the CSV is the run's (the CSV keeps the positions to the digit)
    np.testing.assert_allclose(offline["tool (actual)"][0], live["tool (actual)"][0], rtol=0, atol=1e-9)


@pytest.mark.slow
def test_the_offline_plot_draws_the_stock_of_a_runs_set_registers(project, tmp_path, monkeypatch, capsys):
    out = tmp_path / "out"
    _plotted_planes(monkeypatch, ["run", "lathe_roughing", "--stop-time", "0.5", "--out", str(out),
                                  "--set", "seq.block[1].Xf=2.5"], EXIT_NOT_FINISHED)
    [offline] = _plotted_planes(monkeypatch, ["plot", str(out / "lathe_roughing.csv")])
    assert "stock outline X = 27.5" in offline                # 30 - 2.5 (the system's own: X = 29)
    # a CSV moved away from its run record is plotted with the system's parameter sets, as before
    moved = tmp_path / "moved"
    moved.mkdir()
    (out / "lathe_roughing.csv").rename(moved / "lathe_roughing.csv")
    [bare] = _plotted_planes(monkeypatch, ["plot", str(moved / "lathe_roughing.csv")])
    assert "stock outline X = 29" in bare


def test_a_broken_run_record_is_one_line_and_exit_2(tmp_path, capsys):
    from ncfmu.cli import main
    csv = tmp_path / "lathe_roughing.csv"
    csv.write_text("time,x_axis.pos,z_axis.pos\n0,30,2\n0.1,29,2\n")
    (tmp_path / "lathe_roughing.run.json").write_text("{not json")
    assert main(["plot", str(csv)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "lathe_roughing.run.json: not a run record" in err


# -- the grinder: a feed hold marked; no empty panel for following errors not recorded ---------------------
def _spans(ax) -> dict[str, tuple[float, float]]:
    """The shaded time spans of a panel: label -> (first, last) time they cover."""
    out = {}
    for coll in ax.collections:
        xs = np.concatenate([path.vertices[:, 0] for path in coll.get_paths()]) if coll.get_paths() else []
        if len(xs) and not coll.get_label().startswith("_"):
            out[coll.get_label()] = (float(np.min(xs)), float(np.max(xs)))
    return out


def test_the_grinder_plot_marks_a_feed_hold(ncfmu_run):
    """Before: a feed hold left no mark; the flat stretch of X looked like a dwell."""
    import matplotlib.pyplot as plt

    from ncfmu.plots import result_figure
    held = ncfmu_run("grinder_feed", start_values={"panel.hold_at": 12.0, "panel.release_at": 15.0})
    fig = result_figure(held)
    ax_pos, ax_err = fig.axes
    spans = _spans(ax_pos)
    assert list(spans) == ["feed hold: 1 time, 3 s"]
    start, end = spans["feed hold: 1 time, 3 s"]
    assert start == pytest.approx(12.0, abs=2e-3) and end == pytest.approx(15.0, abs=2e-3)
    assert "feed hold: 1 time, 3 s" in [t.get_text() for t in ax_pos.get_legend().get_texts()]
    assert _spans(ax_err).keys() == spans.keys()                     # the error panel shows it too
    # what is marked is a hold: the infeed stands still in it (its rough feed runs before and after)
    t, x = held.time, held["x_axis.pos"]
    inside = (t > 12.2) & (t < 15.0)
    assert np.ptp(x[inside]) < 1e-4 and x[(t > 15.5) & (t < 16)].min() > x[inside].max()
    plt.close(fig)
    plain = result_figure(ncfmu_run("grinder_feed"))
    assert all(not _spans(ax) for ax in plain.axes)                  # no hold, no mark
    plt.close(plain)


def test_a_run_recorded_without_following_errors_gets_no_empty_panel(ncfmu_run):
    """Before: the second panel said "no following_error recorded" and was otherwise empty (a soak recorded with
    --record to keep it small); now the positions are the figure and the title says what to record."""
    import matplotlib.pyplot as plt
    from numpy.lib import recfunctions as rfn

    from ncfmu.cosim.result import Result
    from ncfmu.plots import result_figure
    run = ncfmu_run("grinder_feed", start_values={"panel.hold_at": 12.0, "panel.release_at": 15.0})
    kept = rfn.repack_fields(run.data[["time", "x_axis.pos", "feed.run", "panel.feed_hold"]])
    fig = result_figure(Result(kept, "grinder_feed"))
    [ax] = fig.axes
    assert "following errors not recorded: --record x_axis.following_error" in ax.get_title()
    assert list(_spans(ax)) == ["feed hold: 1 time, 3 s"]
    plt.close(fig)
