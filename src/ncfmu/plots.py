"""Plots of runs and sweeps (matplotlib, written as PNG).

- :func:`plot_result`: axis positions and commands, following errors, and the tool path in the machine
  plane the system's report names, with its envelope or contour (lathe X-Z with the chuck zone, grinder
  Y-X with its four regions, mill X-Y with the programmed and the corrected contour).
- :func:`plot_sweep`: a sweep's summary metrics against the varied value.
- :func:`bode_figure`: the ServoAxis's open loops over the band that matters, with their margins (for the
  FMU's documentation).
- :func:`plot_signals`: a result of no known system (a single FMU's, a CSV fmpy wrote): its signals over time.
- :func:`read_plot_csv`: a result CSV of any length read as a figure can show it (streamed, decimated).

A run of any length is drawn from what :class:`~ncfmu.cosim.record.DecimatingSink` keeps of it (``--plot``
streams into one; :func:`read_plot_csv` reads a CSV into one): every bucket's extremes and edges, at most
about 2048 buckets, so the memory and the time to draw stay bounded whatever the run's length.
"""

from __future__ import annotations

import csv
import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .systems.outcome import RAN, STATUSES


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_result(result, path: Path) -> Path:
    """Plot a run: positions, following errors and, for a system with a machine plane, the path in it with
    the envelope or the contour of the parameters the run used (see :func:`ncfmu.systems.run_parameters`)."""
    plt = _plt()
    fig = result_figure(result)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def result_figure(result):
    """The figure of :func:`plot_result` (a matplotlib Figure): the positions with what the cycle did when (a
    feed hold, an emergency return), the following errors when they were recorded, the machine plane."""
    from .systems import report_of, run_parameters
    plt = _plt()
    report = report_of(result)
    axes = [a for a in report.axes if f"{a}.pos" in result]
    # the plane needs both of its axes' positions (a sweep's --record may have kept fewer)
    has_plane = report.plane is not None and all(f"{a}.pos" in result for a in (report.plane.horizontal,
                                                                                  report.plane.vertical))
    # a trajectory recorded without the following errors (a run's or a sweep's --record) gets no panel for them
    errors = [a for a in axes if f"{a}.following_error" in result]
    count = 1 + bool(errors) + has_plane
    fig, panels = plt.subplots(count, 1, figsize=(10, 4 * count), squeeze=False)
    ax_pos = panels[0, 0]
    ax_err = panels[1, 0] if errors else None
    t = result.time
    for a in axes:
        line, = ax_pos.plot(t, result[f"{a}.pos"], label=f"{a}.pos (actual)")
        if a in errors:
            ax_pos.plot(t, result[f"{a}.pos"] + result[f"{a}.following_error"], "--", lw=0.8,
                        color=line.get_color(), label=f"{a} command")
    title = f"{result.system}: axis positions"
    if not errors:
        title += " (following errors not recorded: --record " + " ".join(f"{a}.following_error" for a in axes) + ")"
    ax_pos.set(title=title, xlabel="time [s]", ylabel="position [mm]")
    report.draw_time(ax_pos, result)
    if ax_err is not None:
        for a in errors:
            ax_err.plot(t, result[f"{a}.following_error"] * 1000, label=f"{a}")
        ax_err.set(title="following error (command - actual)", xlabel="time [s]", ylabel="error [µm]")
        ax_err.set_xlim(ax_pos.get_xlim())
        report.draw_time(ax_err, result)
    for ax in (ax_pos, ax_err):
        if ax is not None:
            ax.legend(loc="best", fontsize=8)
            ax.grid(True, alpha=0.3)
    if has_plane:
        report.draw_plane(panels[-1, 0], result, run_parameters(result))
    fig.tight_layout()
    return fig


def plot_part(verdict, title: str, path: Path) -> Path:
    """The part check's picture: the part as made over the programmed part, its outline coloured by the
    deviation (+ material left, - gouged), and the deviation along the outline against the tolerance."""
    import shapely
    plt = _plt()
    fig, (ax, ax_dev) = plt.subplots(2, 1, figsize=(10, 10), height_ratios=(3, 2))
    u, v = verdict.axes
    for k, poly in enumerate(shapely.get_parts(verdict.made)):
        xs, ys = poly.exterior.xy
        ax.fill(xs, ys, color="0.85", lw=0, zorder=0, label="part as made" if k == 0 else None)
    for k, poly in enumerate(shapely.get_parts(verdict.programmed)):
        xs, ys = poly.exterior.xy
        ax.plot(xs, ys, color="k", lw=0.6, ls="--", label="programmed part" if k == 0 else None)
    pts = shapely.get_coordinates(shapely.segmentize(verdict.made.boundary, 0.05))
    inside = shapely.contains_xy(verdict.programmed, pts[:, 0], pts[:, 1])
    signed = np.where(inside, -1.0, 1.0) * shapely.distance(shapely.points(pts), verdict.programmed.boundary)
    span = max(verdict.tolerance_mm, float(np.abs(signed).max()))
    sc = ax.scatter(pts[:, 0], pts[:, 1], c=signed * 1000, cmap="coolwarm", vmin=-span * 1000, vmax=span * 1000,
                    s=4, zorder=3)
    fig.colorbar(sc, ax=ax, fraction=0.04, pad=0.01, label="made minus programmed [µm] (+ left, - gouge)")
    for c in verdict.crashes:
        ax.plot(*c.at, "rx", ms=10, mew=2)
        ax.annotate(f"CRASH t = {c.t:.3f} s, {verdict.line_name(c.line)}", c.at, fontsize=8, color="tab:red")
    status = ("CRASH" if verdict.crashed else "within" if verdict.within_tolerance else "OUT OF")
    ax.set(title=f"{title}: the part as made ({status} tolerance {verdict.tolerance_mm:g} mm)", xlabel=f"{u} [mm]",
           ylabel=f"{v} [mm]")
    ax.set_aspect("equal")
    ax.legend(loc="best", fontsize=8)
    ax.grid(True, alpha=0.3)
    along = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))))
    ax_dev.plot(along, signed * 1000, lw=0.8, color="tab:blue", label="made minus programmed")
    for sign in (1, -1):
        ax_dev.axhline(sign * verdict.tolerance_mm * 1000, color="tab:red", ls=":", lw=1,
                       label="tolerance" if sign == 1 else None)
    ax_dev.set(title="deviation along the made part's outline", xlabel="along the outline [mm]",
               ylabel="deviation [µm]")
    ax_dev.legend(loc="best", fontsize=8)
    ax_dev.grid(True, alpha=0.3)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


#: Columns of a sweep's summary that are bookkeeping, not metrics of the machine (``ncfmu.batch`` writes them).
SWEEP_BOOKKEEPING = ("key", "status", "error", "rows", "wall_time", "sim_time")


def _number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def sweep_figure(rows: list[dict[str, str]], title: str):
    """The figure of :func:`plot_sweep` (a matplotlib Figure), from the summary's rows.

    One panel per metric (every column after ``error`` but the bookkeeping ones), against the first varied
    parameter, one line per combination of the others. A variant that ran but did not finish its cycle is an
    open marker (its value at the stop time); a metric it has no value for (nan: e.g. the cycle time of an
    unfinished cycle) is an x on the panel's lower edge; a failed or timed-out variant is a triangle on the
    upper edge. Nothing is left out silently.
    """
    plt = _plt()
    columns = list(rows[0])
    varied = columns[1:columns.index("status")]
    metrics = [c for c in columns[columns.index("error") + 1:] if c not in SWEEP_BOOKKEEPING
               and any(_number(r[c]) is not None for r in rows if r[c] != "")]
    x_name = varied[0]
    xs = [r[x_name] for r in rows]
    numeric = all(_number(x) is not None for x in xs)
    categories = list(dict.fromkeys(xs))
    # a long text value (a part program) is no tick label: the ticks are numbered, the values listed below
    keyed = not numeric and any(len(c) > SWEEP_TICK_CHARS for c in categories)
    ticks = [f"#{i + 1}" for i in range(len(categories))] if keyed else categories
    key = "\n".join(f"#{i + 1}: {_shortened(c)}" for i, c in enumerate(categories)) if keyed else ""

    def x_of(r: dict[str, str]) -> float:
        return float(r[x_name]) if numeric else float(categories.index(r[x_name]))
    ran = [r for r in rows if r["status"] in RAN]
    stopped = [r for r in rows if r["status"] not in RAN]
    groups = list(dict.fromkeys(", ".join(f"{v}={r[v]}" for v in varied[1:]) for r in rows))
    colours = {g: f"C{i % 10}" for i, g in enumerate(groups)}
    fig, axes = plt.subplots(len(metrics) or 1, 1, figsize=(10, 2.6 * max(1, len(metrics))), squeeze=False)
    for ax, metric in zip(axes[:, 0], metrics):
        edges = ax.get_xaxis_transform()              # x in data, y in axes fractions: the panel's edges
        said: set[str] = set()

        def once(text: str, said: set[str] = said) -> str:
            """The legend label the first time in this panel, none after."""
            if text in said:
                return "_nolegend_"
            said.add(text)
            return text
        ax.margins(y=0.2)                             # bands at the edges for the markers of missing values
        for group in groups:
            mine = [r for r in ran if ", ".join(f"{v}={r[v]}" for v in varied[1:]) == group]
            colour = colours[group]
            if not mine:
                continue
            done = sorted((x_of(r), float(r[metric])) for r in mine
                          if r["status"] == "ok" and np.isfinite(float(r[metric])))
            ax.plot([p[0] for p in done], [p[1] for p in done], "o-", color=colour, label=group or metric)
            open_ = [(x_of(r), float(r[metric])) for r in mine
                     if r["status"] == "unfinished" and np.isfinite(float(r[metric]))]
            if open_:
                ax.plot([p[0] for p in open_], [p[1] for p in open_], "o", mfc="none", color=colour,
                        label=once("unfinished: value at the stop time"))
            for status, marker in (("crashed", "X"), ("out_of_tolerance", "s")):
                bad = [(x_of(r), float(r[metric])) for r in mine
                       if r["status"] == status and np.isfinite(float(r[metric]))]
                if bad:
                    ax.plot([p[0] for p in bad], [p[1] for p in bad], marker, ms=8, color=colour, mec="tab:red",
                            mew=1.5, ls="none", label=once(f"{status.replace('_', ' ')}: the part rejected"))
            nans = [x_of(r) for r in mine if not np.isfinite(float(r[metric]))]
            if nans:
                ax.plot(nans, [0.05] * len(nans), "x", ms=9, mew=2, color=colour, transform=edges, clip_on=False,
                        label=once("no value (nan): cycle not finished"))
        for status, edge in (("failed", "tab:red"), ("timeout", "tab:purple")):
            for group in groups:
                at = [x_of(r) for r in stopped if r["status"] == status
                      and ", ".join(f"{v}={r[v]}" for v in varied[1:]) == group]
                if at:
                    ax.plot(at, [0.95] * len(at), "v", ms=9, mfc=colours[group], mec=edge, mew=2, ls="none",
                            transform=edges, clip_on=False, label=f"{status}, no value" + (f": {group}" if group
                                                                                           else ""))
        ax.set(xlabel=x_name + (" (values listed below)" if keyed else ""), ylabel=metric)
        if not numeric:
            ax.set_xticks(range(len(categories)), ticks)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    counts = {s: sum(r["status"] == s for r in rows) for s in STATUSES}
    axes[0, 0].set_title(f"{title}: " + ", ".join(f"{n} {s}" for s, n in counts.items() if n or s == "ok"))
    if key:
        height = fig.get_figheight()
        key_height = 0.2 + 0.16 * (key.count("\n") + 1)         # inches under the panels
        fig.set_figheight(height + key_height)
        fig.text(0.01, 0.1 / (height + key_height), f"{x_name}:\n{key}", fontsize=7, va="bottom", family="monospace")
        fig.tight_layout(rect=(0, (key_height + 0.16) / (height + key_height), 1, 1))
    else:
        fig.tight_layout()
    return fig


#: A text value of a sweep longer than this is numbered on the axis and listed below the panels.
SWEEP_TICK_CHARS = 16
#: How much of a long text value the list below the panels shows.
SWEEP_KEY_CHARS = 110


def _shortened(text: str) -> str:
    """A long text value (a program) on one line of the list: its lines joined, cut at SWEEP_KEY_CHARS."""
    one = " | ".join(line.strip() for line in text.splitlines() if line.strip())
    return one if len(one) <= SWEEP_KEY_CHARS else one[:SWEEP_KEY_CHARS - 3] + "..."


def plot_sweep(summary_csv: Path, path: Path) -> Path:
    """Each metric of a sweep's summary against the first varied parameter (see :func:`sweep_figure`)."""
    plt = _plt()
    with open(summary_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError(f"{summary_csv} has no rows")
    fig = sweep_figure(rows, f"sweep {Path(summary_csv).parent.name}")
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


# -- a result of no known system: a single FMU's, or a CSV another tool wrote --------------------------
#: changing numeric signals drawn at most; the title says how many more the file has
MAX_SIGNAL_PANELS = 24


@dataclass
class SignalPanels:
    """How :func:`plot_signals` lays out a result."""

    numbers: list[str]                  # numbers that change: a panel each, in the file's order
    booleans: list[str]                 # Booleans: together on one panel, as logic traces
    constant: dict[str, float]          # numbers that never change: listed with their value, not drawn


def signal_panels(result) -> SignalPanels:
    panels = SignalPanels([], [], {})
    for name in result.names:
        column = result[name]
        if column.dtype == np.bool_:
            panels.booleans.append(name)
        elif np.array_equal(column, np.full_like(column, column[0]), equal_nan=True):
            panels.constant[name] = float(column[0])
        else:
            panels.numbers.append(name)
    return panels


def plot_signals(result, path: Path) -> Path:
    """Every recorded signal over time, for a result that names no system ncfmu knows (a single FMU run by
    fmpy, another tool's CSV): each changing number on a panel of its own (whole-numbered ones as steps), the
    Booleans as logic traces on one panel, the constant numbers listed with their values."""
    import textwrap
    plt = _plt()
    panels = signal_panels(result)
    drawn = panels.numbers[:MAX_SIGNAL_PANELS]
    rows = max(1, len(drawn) + bool(panels.booleans))
    logic_height = 0.45 * len(panels.booleans) + 0.6
    heights = [1.0] * len(drawn) + ([logic_height / 1.9] if panels.booleans else [])
    listed = ", ".join(f"{name} = {value:g}" for name, value in panels.constant.items())
    note = textwrap.fill(f"constant over the run: {listed}", 140) if listed else ""
    note_height = 0.2 + 0.16 * (note.count("\n") + 1) if note else 0.0          # inches under the panels
    height = 1.9 * sum(heights or [1.0]) + 1.0 + note_height
    fig, axes = plt.subplots(rows, 1, figsize=(10, height), sharex=True, squeeze=False,
                             gridspec_kw={"height_ratios": heights or [1.0]})
    t = result.time
    for ax, name in zip(axes[:, 0], drawn):
        values = result[name]
        whole = bool(np.all(np.isfinite(values) & (values == np.round(values))))
        ax.plot(t, values, lw=1.0, drawstyle="steps-post" if whole else "default")
        ax.set_title(name, loc="left", fontsize=9)
        ax.grid(True, alpha=0.3)
    if panels.booleans:
        ax = axes[len(drawn), 0]
        for i, name in enumerate(panels.booleans):
            color = f"C{i % 10}"
            ax.fill_between(t, i, i + 0.7 * result[name], step="post", alpha=0.4, color=color, lw=0)
            ax.step(t, i + 0.7 * result[name], where="post", lw=1.0, color=color)
        ax.set_yticks([i + 0.35 for i in range(len(panels.booleans))], panels.booleans, fontsize=8)
        ax.set_ylim(-0.2, len(panels.booleans))
        ax.set_title("Booleans (raised: true)", loc="left", fontsize=9)
        ax.grid(True, axis="x", alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    title = f"{result.system or 'result'}: recorded signals over {t[0]:g}..{t[-1]:g} s"
    if len(panels.numbers) > len(drawn):
        title += f" (the first {len(drawn)} of {len(panels.numbers)} changing numbers)"
    fig.suptitle(title)
    if note:
        fig.text(0.01, 0.1 / height, note, fontsize=8, va="bottom")
    fig.tight_layout(rect=(0, note_height / height, 1, 1))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


# -- a result CSV of any length, read as a figure can show it ------------------------------------------------
#: rows parsed at a time by :func:`read_plot_csv`
CSV_CHUNK_ROWS = 16384


def read_plot_csv(path: Path, buckets: int | None = None, chunk_rows: int = CSV_CHUNK_ROWS):
    """A result CSV (fmpy's layout, what :meth:`Result.from_csv <ncfmu.cosim.result.Result.from_csv>` reads, with
    its checks and messages) read ``chunk_rows`` lines at a time into a
    :class:`~ncfmu.cosim.record.DecimatingSink`: a :class:`~ncfmu.cosim.result.Result` of the rows it keeps, in
    memory bounded by its buckets whatever the file's length (a CSV shorter than the buckets is kept whole)."""
    from .cosim.record import PLOT_BUCKETS, DecimatingSink
    from .errors import SystemDefinitionError
    path = Path(path)
    sink = DecimatingSink(buckets=PLOT_BUCKETS if buckets is None else buckets)
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:    # a BOM (Excel's "CSV UTF-8") is not a name
            first = next(csv.reader([f.readline()]), None)
            if first is None or not any(cell.strip() for cell in first):
                raise SystemDefinitionError(f"{path}: the result CSV is empty (expected a header time,NAME,...)")
            header = [h.strip() for h in first]
            if header[0] != "time":
                raise SystemDefinitionError(f"{path}: a result CSV needs a first column 'time', not {header[0]!r}")
            for j, name in enumerate(header):
                if name in header[:j]:
                    raise SystemDefinitionError(f"{path}: line 1: column {name!r} twice")
            booleans: list[bool] | None = None             # per column, from the first chunk
            dtype = np.dtype([])
            line = 2                                       # the file's line number of the chunk's first line
            while True:
                lines = list(itertools.islice(f, chunk_rows))
                if not lines:
                    break
                columns = _plain_columns(lines, len(header), booleans)
                if columns is None:                        # anything but plain numbers: read as from_csv reads
                    rows = [(k, row) for k, row in enumerate(csv.reader(lines), start=line)
                            if any(cell.strip() for cell in row)]
                    columns = _csv_columns(path, header, rows, booleans) if rows else None
                line += len(lines)
                if columns is None:
                    continue
                if booleans is None:
                    booleans = [c.dtype == np.bool_ for c in columns]
                    dtype = np.dtype([(name, c.dtype) for name, c in zip(header, columns)])
                    sink.open([(name, dtype[name]) for name in header])
                data = np.empty(len(columns[0]), dtype=dtype)
                for name, c in zip(header, columns):
                    data[name] = c
                sink.write(data)
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise SystemDefinitionError(f"{path}: cannot read the result CSV: {err}") from None
    if booleans is None:
        raise SystemDefinitionError(f"{path}: the result CSV has a header and no rows")
    sink.close(True)
    return sink.result()


#: what a chunk of plain numbers holds (the CSV ncfmu writes): digits, signs, points, exponents, nan and inf
_PLAIN = b"0123456789+-.eE,naifNAIF \t\r\n"


def _plain_columns(lines: list[str], width: int, booleans: list[bool] | None) -> list[np.ndarray] | None:
    """The columns of a chunk of plain numbers, parsed by numpy at C speed; None when it is anything else (a
    True/False, a quote, a blank row, a mistake): then the careful reading says what, where."""
    if booleans is not None and any(booleans):
        return None
    try:
        if "".join(lines).encode("ascii").translate(None, _PLAIN):
            return None                                    # a character no plain number has
    except UnicodeEncodeError:
        return None
    try:
        table = np.loadtxt(lines, delimiter=",", dtype=np.float64, comments=None, ndmin=2)
    except ValueError:
        return None
    if table.shape[1] != width or len(table) != sum(1 for text in lines if text.strip()) \
            or not np.isfinite(table[:, 0]).all():
        return None
    return [table[:, j].copy() for j in range(width)]


def _csv_columns(path: Path, header: list[str], rows: list[tuple[int, list[str]]],
                 booleans: list[bool] | None) -> list[np.ndarray]:
    """The columns of a chunk of a result CSV's rows (file line, cells), each checked as ``Result.from_csv``
    checks the whole file; ``booleans``: which columns the chunks before found True/False (None: the first)."""
    from .cosim.result import csv_column
    from .errors import SystemDefinitionError
    for k, row in rows:
        if len(row) != len(header):
            raise SystemDefinitionError(f"{path}: line {k}: {len(row)} values for {len(header)} columns")
    columns = []
    for j, (name, raw) in enumerate(zip(header, zip(*(row for _, row in rows)))):
        cells = [c.strip() for c in raw]
        words = {c.lower() for c in cells}
        boolean = j > 0 and words <= {"true", "false"}
        if booleans is not None and boolean != booleans[j]:
            # a column is Booleans or numbers in the whole file: say where this chunk breaks the rule
            k, cell = next(((k, c) for (k, _), c in zip(rows, cells)
                            if (c.lower() in ("true", "false")) != booleans[j]))
            kind = "True/False" if booleans[j] else "a number"
            raise SystemDefinitionError(f"{path}: line {k}: {name} = {cell!r}: not {kind} as in the lines before")
        columns.append(csv_column(path, name, rows, cells, boolean))
    bad_time = np.flatnonzero(~np.isfinite(columns[0]))
    if bad_time.size:
        raise SystemDefinitionError(f"{path}: line {rows[int(bad_time[0])][0]}: time must be finite")
    return columns
