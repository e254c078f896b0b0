"""The ``ncfmu`` command: build, run, validate."""

from __future__ import annotations

import argparse
import itertools
import math
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

from .errors import FmuCrashed, NcfmuError
from .exitcodes import EXIT_HELP, EXIT_NOT_FINISHED, EXIT_OK, EXIT_PROBLEMS, EXIT_REFUSED
from .ports import is_integer_text, parse_integer, parse_real

if TYPE_CHECKING:
    from .cosim.ssp import System


def epilog() -> str:
    """The systems and their instances, from their definitions (nothing here restates them)."""
    from .systems import SYSTEMS, get_system
    systems = [get_system(name) for name in SYSTEMS]
    listed = ", ".join(f"{s.name}{' (default)' if s.name == 'lathe_roughing' else ''}" for s in systems)
    instances = "; ".join(f"{s.name} {', '.join(c.name for c in s.components)}" for s in systems)
    return f"Systems: {listed}. Instances: {instances}."


class _Parser(argparse.ArgumentParser):
    """argparse with ncfmu's error line: ``ncfmu <command>: <what is wrong>`` and exit status 2, not the usage
    block (``--help`` still shows it)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: {message}\n")


def _negative_values(argv: list[str]) -> list[str]:
    """``--step -1e-3`` as ``--step=-1e-3``.

    argparse takes a word that starts with '-' for an option unless it looks like ``-5`` or ``-0.5``, so a
    negative number in exponent form (or ``-inf``) after an option came out as "expected one argument". Joined
    to its option it is a value, which the option's own rule then judges.
    """
    out: list[str] = []
    for word in argv:
        previous = out[-1] if out else ""
        if word.startswith("-") and previous.startswith("--") and previous != "--" and "=" not in previous:
            try:
                parse_real(word)
            except ValueError:
                pass
            else:
                out[-1] = f"{previous}={word}"
                continue
        out.append(word)
    return out


#: options of a command that take a number that must be > 0 and finite (checked before the command runs)
POSITIVE = {"run": ("--stop-time", "--step", "--branch-at", "--tolerance", "--max-depth"),
            "sweep": ("--connect-timeout",)}


def _check_positive(args: argparse.Namespace) -> None:
    for option in POSITIVE.get(args.command, ()):
        value = getattr(args, option[2:].replace("-", "_"))
        if value is not None and not math.isfinite(value):
            raise NcfmuError(f"{option} {value!r}: must be > 0 and finite")
        if value is not None and not value > 0:
            raise NcfmuError(f"{option} {value!r}: must be > 0")


def _output_folder(out: str) -> None:
    """``--out``: a folder, made now -- before a run that would only fail to write its results at the end."""
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise NcfmuError(f"--out {path}: is a file, not a folder")
    if path.is_symlink() and not path.exists():       # mkdir would only say "File exists"
        raise NcfmuError(f"--out {path}: a symbolic link to {os.readlink(path)}, which does not exist (make that "
                         "folder, or give another --out)")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise NcfmuError(f"--out {path}: cannot make the folder: {err.strerror or err}") from None


def _parse_set(items: list[str]) -> dict[str, object]:
    values: dict[str, object] = {}
    for item in items or []:
        name, eq, raw = item.partition("=")
        if not eq or "." not in name:
            raise NcfmuError(f"--set {item!r}: expected INSTANCE.VARIABLE=VALUE, e.g. seq.block[1].Xd=0.4")
        low = raw.strip().lower()
        if low in ("true", "false"):
            values[name] = low == "true"
        else:                             # a number in ASCII decimal, else text (a String's value; a number's
            try:                          # variable refuses it, naming the rule)
                values[name] = parse_integer(raw) if is_integer_text(raw) else parse_real(raw)
            except ValueError:
                values[name] = raw
    return values


def _real_option(text: str) -> float:
    """The value of a numeric option (``--step 1e-3``), by the one parser of numbers written as text."""
    try:
        return parse_real(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def _integer_option(text: str) -> int:
    try:
        return parse_integer(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def _summary(result, report_lines: list[str] | None = None) -> str:
    """The run's summary: the report's lines from its trajectory, or ``report_lines`` computed as it ran."""
    from .systems import report_of, run_parameters
    lines = [f"system {result.system}: simulated {result.end_time:.3f} s in {result.wall_time:.2f} s wall "
             f"(simulated/wall-clock ratio {result.realtime_factor:.1f})"]
    lines += (report_of(result).summary(result, run_parameters(result)) if report_lines is None
              else report_lines)
    if getattr(result, "ended_by", ""):
        lines.append(f"  ended: {result.ended_by}")
    lines += [f"  [warning] {w}" for w in getattr(result, "warnings", [])]
    for _inst, msgs in result.messages.items():
        for level, text in msgs:
            if level in ("warning", "error", "fatal"):
                lines.append(f"  [{level}] {text}")
    return "\n".join(lines)


def _unreached_lines(system: str, runs: list[dict[str, object]], option: dict[str, str],
                     opened: System | None = None) -> list[str]:
    """Summary lines warning of the settings (of any of ``runs``) that reach no connected port of ``system``
    (the rule: ``ncfmu.systems.reach``); ``option`` names the command-line option of each setting; ``opened``: the
    system an .ssp path held, as the run read it (not read again)."""
    from .cosim.ssp import read_ssp
    from .systems import SYSTEMS, get_system
    from .systems.reach import unreached
    definition = (opened or read_ssp(Path(system))) if system.endswith(".ssp") else get_system(system) \
        if system in SYSTEMS else None
    if definition is None:
        return []
    why: dict[str, str] = {}
    where: dict[str, list[object]] = {}
    for values in runs:
        for name, reason in unreached(definition, values).items():
            why.setdefault(name, reason)
            if values[name] not in where.setdefault(name, []):
                where[name].append(values[name])
    return [f"  [warning] {option.get(name, '--set')} {name}={','.join(map(str, where[name]))}: {reason}"
            for name, reason in why.items()]


def _replace_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--replace", action="append", default=[], metavar="INSTANCE=PATH.fmu",
                   help="run another FMU in place of an instance (connections kept by variable name; the old "
                        "parameters applied where the new FMU has them); repeatable")
    p.add_argument("--map", action="append", default=[], metavar="INSTANCE.THEIRS=OURS",
                   help="a replacing FMU's name for an old connector, e.g. --map x_axis.x=pos; repeatable")


def _in_words(err: NcfmuError) -> str:
    """An error's one line: an FMU that refused its parameters by what it said (a program's lines in a CNC's words:
    ``seq: parameter refused: program: line 3 (N30): G112: ...``), not by the FMI call and status it returned
    (which its log keeps); anything else as it is."""
    return getattr(err, "refusal", "") or str(err)


def _kind_options(p: argparse.ArgumentParser) -> None:
    """``--pure``/``--compiled`` of the commands that build what they run (run, sweep, serve)."""
    kind = p.add_mutually_exclusive_group()
    kind.add_argument("--pure", dest="kind", action="store_const", const="pure", default=None,
                      help="(re)build the FMUs with the controllers as Python sources only, and keep that kind: later "
                           "commands without --compiled run pure FMUs too (the kind is recorded in fmus/)")
    kind.add_argument("--compiled", dest="kind", action="store_const", const="compiled",
                      help="(re)build the FMUs with the controllers compiled (mypyc, the default kind), and keep it. "
                           "Without either flag the FMUs are kept as the last build made them ('ncfmu build' "
                           "without --pure: compiled)")


def _build_kind(args) -> None:
    """``--pure``/``--compiled``: build the project's FMUs of that kind now (recorded in fmus/, so the command's own
    build keeps it)."""
    if getattr(args, "kind", None) is not None:
        from .project import build
        build(args.root, only_stale=True, pure=args.kind == "pure")


def _program_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--program", default=None, metavar="FILE",
                   help="a part program for the system's program parameter (seq.program on the lathes, "
                        "contour.program on the mill), read from FILE ('-': standard input)")


def _program_value(args) -> dict[str, object]:
    """``--program FILE``: {the system's program parameter: the file's text}, or {} without it. A system with no
    program parameter, or with several, is refused (exit 2)."""
    if args.program is None:
        return {}
    source = "standard input" if args.program == "-" else args.program
    try:
        text = sys.stdin.read() if args.program == "-" else Path(args.program).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise NcfmuError(f"--program {source}: cannot read it ({getattr(err, 'strerror', None) or err})") from None
    from .systems import SYSTEMS, get_system
    from .systems.settable import settable
    if args.system in SYSTEMS:
        rows = settable(get_system(args.system))
    else:
        from .cosim.ssp import read_ssp
        from .project import model_descriptions
        archive = Path(args.system)
        system = read_ssp(archive)
        rows = settable(system, model_descriptions(archive, system).__getitem__)
    names = [r.name for r in rows if r.kind.startswith("parameter") and r.name.split(".", 1)[1] == "program"]
    if len(names) != 1:
        raise NcfmuError(f"--program {source}: {args.system} has "
                         + ("no program parameter (INSTANCE.program): it runs no part program" if not names else
                            f"more than one program parameter ({', '.join(names)}): give one with --set NAME=...")
                         )
    given = [item.partition("=")[0] for item in (getattr(args, "set", None) or [])]
    if names[0] in given:
        raise NcfmuError(f"--program and --set {names[0]}=... both give {names[0]}: give one")
    return {names[0]: text}


def _prepare_source(args) -> list[str]:
    """``args.system`` (a name, .ssp, .ssd, system folder or .fmu, with --replace/--map) made the path of the .ssp
    the command runs; returns the replacement's warning lines."""
    from .project import prepared_archive
    if args.system in _shipped_names() and not args.replace and not args.map:
        return []
    archive, warnings = prepared_archive(args.system, args.replace, args.map, args.root)
    args.system = str(archive)
    return warnings


def _shipped_names() -> set[str]:
    from .systems import SYSTEMS
    return set(SYSTEMS)


def cmd_pack(args) -> int:
    """A user's system (an .ssd with its folder, an unpacked folder, an .ssp or a bare .fmu, with --replace/--map)
    written as one .ssp archive."""
    from .cosim.ssp import read_ssp
    from .files import write_atomic
    warnings = _prepare_source(args)
    if args.system in _shipped_names():
        from .project import system_archive
        args.system = str(system_archive(args.system, args.root))
    out = Path(args.output)
    if out.suffix != ".ssp":
        raise NcfmuError(f"--output {out}: must end in .ssp")
    system = read_ssp(Path(args.system))
    write_atomic(out, Path(args.system).read_bytes())
    print(f"packed {system.name} ({len(system.components)} components: "
          f"{', '.join(c.name for c in system.components)}) -> {out}")
    for w in warnings:
        print(f"  [warning] {w}")
    return 0


def cmd_build(args) -> int:
    from .project import build
    out = build(args.root, only_stale=not args.force, pure=args.pure)
    for kind, paths in out.items():
        for p in paths:
            print(f"{kind:4s} {p}")
    return 0


def _parse_branches(items: list[str]) -> list[dict[str, object]]:
    """``--branch-set panel.emergency_at=12,21,31`` -> one variant per value (zipped across options)."""
    columns = {}
    for item in items or []:
        name, eq, raw = item.partition("=")
        if not eq:
            raise NcfmuError(f"--branch-set {item!r}: expected INSTANCE.VARIABLE=V1,V2,...")
        columns[name] = [next(iter(_parse_set([f"{name}={v}"]).values())) for v in raw.split(",")]
    lengths = {len(v) for v in columns.values()}
    if len(lengths) > 1:
        raise NcfmuError(f"--branch-set options need the same number of values, got {sorted(lengths)}")
    n = lengths.pop() if lengths else 1
    return [{name: values[i] for name, values in columns.items()} for i in range(n)]


def _drawing(args):
    """The part drawn (``--drawing FILE.dxf``), read before anything runs; None: none given."""
    if args.drawing is None:
        return None
    if args.no_part_check:
        raise NcfmuError("--drawing and --no-part-check together: the drawing is what the part check judges against")
    from .systems.drawing import read_drawing
    return read_drawing(args.drawing)


def _run_streamed(args, start_values: dict[str, object]):
    """Run with the rows streamed to ``OUT/SYSTEM.csv`` (through ``SYSTEM.csv.partial``, renamed when the run
    completed) and the summary computed as the run goes; ``--plot`` keeps what a figure can show of it (a
    :class:`~ncfmu.cosim.record.DecimatingSink`, bounded whatever the run's length). Prints the summary; returns
    the result, where its CSV is, the system run (its .ssp read once), the summary and the rows to plot (or None)."""
    import math

    from .cosim.interrupts import stopped_by
    from .cosim.master import CHECK_INTERVAL, InputTable, deferred_interrupts, steps_per_row
    from .cosim.record import CsvSink, DecimatingSink, RecordWriteError
    from .project import OpenSystem, ScaledSink, recording, system_archive
    from .systems.outcome import RUN_LIMIT, default_stop_time, halted, watched
    from .systems.part import TOLERANCE, PartSettings, with_part_settings, without_part_check
    from .systems.report import start_parameters
    archive = system_archive(args.system, args.root)
    if args.nose_radius is not None and not (args.nose_radius >= 0 and math.isfinite(args.nose_radius)):
        raise NcfmuError(f"--nose-radius {args.nose_radius!r}: must be >= 0 and finite (0: a sharp point)")
    settings = PartSettings(TOLERANCE if args.tolerance is None else args.tolerance, args.nose_radius,
                            args.max_depth, _drawing(args))
    csv_sink = plotted = None
    try:
        with deferred_interrupts():
            inputs = InputTable.from_csv(args.input) if args.input else None
            with OpenSystem(archive, args.mode) as opened:
                system = opened.system
                step = system.step_size if args.step is None else args.step
                # a system with a done signal runs until its work is done, --stop-time (default RUN_LIMIT) the limit;
                # one without (a bare FMU) to --stop-time, default the system's
                report = opened.report()
                report = without_part_check(report) if args.no_part_check else with_part_settings(report, settings)
                # an input CSV with its --stop-time (a served session's replay) follows the input's timeline: what
                # came after a done -- a restart, a second part -- is replayed too; a crash or an alarm still halts
                replay = args.input is not None and args.stop_time is not None
                to_done = not replay and report.ends_when_done(start_parameters(system.components, start_values))
                stop = default_stop_time(system.stop_time, to_done) if args.stop_time is None else args.stop_time
                rows = None
                # the CSV's size checked against the disk for the whole span -- for a run to done, only for a limit
                # beyond RUN_LIMIT (the run's length is where its work ends, not the limit; a billion s is a mistake)
                if step > 0 and math.isfinite(stop / step) and (not to_done or stop > RUN_LIMIT):
                    rows = int(round(stop / step)) // steps_per_row(args.output_interval, step) + 1
                if settings.drawing is not None:        # refused for this system before any file is written
                    from .systems.part import check_drawing_for
                    check_drawing_for(opened.report(), settings.drawing)
                _run_record_path(Path(args.out) / f"{system.name}.csv").unlink(missing_ok=True)    # an earlier run's
                csv_sink = CsvSink(Path(args.out) / f"{system.name}.csv", expected_rows=rows,
                                   run=f"stop time {stop:g} s at a step of {step:g} s")
                # the summary reads every step; the CSV gets the --record columns at the --output-interval; the
                # plot, every step decimated to what a figure shows (its axes in mm, as the summary's)
                how = recording(opened, start_values, csv_sink, args.record, args.output_interval, args.step,
                                in_mm=True, report=report)    # a user's axis in m: the report reads mm
                if args.plot:
                    plotted = DecimatingSink(system.name)
                    how.sinks.append(ScaledSink(plotted, how.scales) if how.scales else plotted)
                accumulator = how.summary
                assert accumulator is not None
                # asked at the CSV's rows (a whole number of them, about every CHECK_INTERVAL s): the last row is
                # at most that long after the work ended
                row_time = steps_per_row(args.output_interval, step) * step
                result = opened.run(stop_time=stop, step_size=args.step, start_values=start_values,
                                    inputs=inputs, keep=False, until=lambda: halted(accumulator, at_done=to_done),
                                    check_interval=row_time * max(1, round(CHECK_INTERVAL / row_time)),
                                    watch=watched(accumulator), **how.run_arguments())
                if not result.ended_by and to_done:
                    result.ended_by = f"the --stop-time limit {stop:g} s reached"
    except KeyboardInterrupt as err:
        stopped, status = stopped_by(err)
        where = _where_stopped(csv_sink) if csv_sink is not None else "no rows recorded"
        print(f"ncfmu run: {stopped}: {where}", file=sys.stderr)
        raise SystemExit(status) from None
    except RecordWriteError as err:       # the disk full: whole rows kept, said as for Ctrl-C
        if csv_sink is None or csv_sink.final_path is None:
            raise
        raise NcfmuError(f"writing the rows failed ({err.reason}): {_where_stopped(csv_sink)}") from None
    except FmuCrashed as err:             # a foreign FMU's process died: the run did not finish, its rows are kept
        where = _where_stopped(csv_sink) if csv_sink is not None and csv_sink.final_path is not None \
            else "no rows recorded"
        print(f"ncfmu run: {err}: {where}", file=sys.stderr)
        raise SystemExit(EXIT_NOT_FINISHED) from None
    except NcfmuError as err:
        if csv_sink is None or csv_sink.final_path is None:
            raise
        raise NcfmuError(f"{_in_words(err)} ({_where_stopped(csv_sink)})") from None
    result.system = system.name
    print(_summary(result, accumulator.summary()))
    parameters = result.parameters or start_parameters(system.components, start_values)
    if csv_sink.final_path is not None:
        _write_run_record(csv_sink.final_path, system.name, parameters)
    shown = None
    if plotted is not None:
        shown = plotted.result()
        shown.parameters, shown.models = parameters, result.models
    return result, csv_sink.final_path, system, accumulator, shown


#: what ``ncfmu run`` keeps beside OUT/SYSTEM.csv for ``ncfmu plot``: the parameters the run applied (a part
#: program, --set values), which a CSV has no place for
RUN_RECORD_SUFFIX = ".run.json"
RUN_RECORD_FORMAT = "ncfmu-run/1"


def _run_record_path(csv: Path) -> Path:
    return csv.with_name(csv.name.removesuffix(".csv") + RUN_RECORD_SUFFIX)


def _write_run_record(csv: Path, system: str, parameters) -> Path:
    """OUT/SYSTEM.run.json beside the run's CSV: its system and the parameters it applied (instance ->
    variable -> value), so the offline plot draws what ``--plot`` drew (e.g. a part program's profile)."""
    import json

    def plain(value: object) -> object:
        return value.item() if hasattr(value, "item") else value      # a numpy scalar: its Python value
    record = {"format": RUN_RECORD_FORMAT, "system": system, "csv": csv.name,
              "parameters": {inst: {k: plain(v) for k, v in values.items()} for inst, values in parameters.items()}}
    path = _run_record_path(csv)
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    os.replace(tmp, path)
    return path


def _read_run_record(csv: Path, system: str) -> dict[str, dict[str, object]] | None:
    """The parameters of OUT/SYSTEM.run.json beside ``csv`` when it is that system's run record, else None."""
    import json
    path = _run_record_path(csv)
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError) as err:
        raise NcfmuError(f"{path}: not a run record of 'ncfmu run' ({err}); delete it to plot without it") from None
    parameters = record.get("parameters") if isinstance(record, dict) else None
    if (not isinstance(record, dict) or record.get("format") != RUN_RECORD_FORMAT or not isinstance(parameters, dict)
            or not all(isinstance(v, dict) for v in parameters.values())):
        raise NcfmuError(f"{path}: not a run record of 'ncfmu run' (format {RUN_RECORD_FORMAT}, parameters by "
                         "instance); delete it to plot without it")
    if record.get("system") != system:
        return None                       # another system's record (the CSV was renamed or --system differs)
    return parameters


def _where_stopped(sink) -> str:
    if not sink.rows:
        return f"no rows recorded ({sink.final_path} has the header only)"
    return f"{sink.rows} rows up to t = {sink.stopped_at:.3f} s in {sink.final_path} (the run did not finish)"


def cmd_run(args) -> int:
    from .project import simulate_branches
    replace_warnings = _prepare_source(args)
    program = _program_value(args)
    if args.branch_at is not None:
        if args.input:
            raise NcfmuError("--input and --branch-at together: branches start from a saved state and take no input "
                             "CSV; run the input without --branch-at, or branch with --branch-set")
        if args.drawing is not None:
            raise NcfmuError("--drawing and --branch-at together: the branches' summaries judge the programmed part; "
                             "run the drawing without --branch-at")
        variants = _parse_branches(args.branch_set)
        results = simulate_branches(args.system, args.branch_at, variants, stop_time=args.stop_time,
                                    start_values={**_parse_set(args.set), **program}, mode=args.mode,
                                    root=args.root)
        out = Path(args.out)
        for i, (variant, result) in enumerate(zip(variants, results)):
            csv = result.to_csv(out / f"{result.system}_branch{i}.csv")
            _write_run_record(csv, result.system, result.parameters)
            label = ", ".join(f"{k}={v}" for k, v in variant.items()) or "no change"
            print(f"branch {i} from t = {args.branch_at} s ({label}):")
            print(_summary(result))
            print(f"  results: {csv}")
        base = _parse_set(args.set)
        for line in _unreached_lines(args.system, [{**base, **v} for v in variants],
                                     dict.fromkeys(variants[0], "--branch-set")):
            print(line)
        return 0
    start_values = {**_parse_set(args.set), **program}
    if args.output_interval is not None and not (args.output_interval > 0 and args.output_interval < float("inf")):
        raise NcfmuError(f"--output-interval {args.output_interval!r}: must be a number of seconds > 0")
    result, csv, system, accumulator, shown = _run_streamed(args, start_values)
    for line in replace_warnings:
        print(f"  [warning] {line}")
    out = Path(args.out)
    for line in _unreached_lines(args.system, [start_values], {}, system):
        print(line)
    print(f"  results: {csv}")
    from .systems.part import verdict_of
    verdict = verdict_of(accumulator)
    if verdict is not None:
        import json

        from .files import write_atomic
        part_json = out / f"{result.system}.part.json"
        write_atomic(part_json, (json.dumps(verdict.as_json(), indent=1) + "\n").encode())
        print(f"  part check: {part_json}")
    if args.plot:
        try:
            import matplotlib  # noqa: F401

            from .plots import plot_part, plot_result
        except ImportError:
            raise NcfmuError("--plot needs matplotlib: pip install -e '.[plot]'") from None
        print(f"  plot: {plot_result(shown, out / f'{result.system}.png')}")
        if verdict is not None and verdict.made is not None:
            print(f"  plot: {plot_part(verdict, result.system, out / f'{result.system}.part.png')}")
    from .systems.outcome import outcome
    came_out = outcome(accumulator)
    if came_out.why:
        print(f"  {came_out.status}: {came_out.why} (exit status {came_out.exit_status})")
    return came_out.exit_status


def _parse_vary(items: list[str]) -> dict[str, list[object]]:
    vary: dict[str, list[object]] = {}
    for item in items or []:
        name, eq, raw = item.partition("=")
        if not eq or not raw:
            raise NcfmuError(f"--vary {item!r}: expected INSTANCE.VARIABLE=V1,V2,... "
                             "e.g. --vary seq.block[1].Xd=0.4,0.5")
        vary[name] = [next(iter(_parse_set([f"{name}={v}"]).values())) for v in raw.split(",")]
    if not vary:
        raise NcfmuError("sweep needs at least one --vary INSTANCE.VARIABLE=V1,V2,...")
    return vary


def cmd_sweep(args) -> int:
    from .batch import STATUSES, SweepStopped, sweep
    from .cosim.interrupts import Interrupted, deferred_interrupts, raised_interrupts, stopped_by
    for name, value in (("--timeout", args.timeout), ("--output-interval", args.output_interval),
                        ("--stop-time", args.stop_time)):
        if value is not None and not (value > 0 and value < float("inf")):
            raise NcfmuError(f"{name} {value!r}: must be a number > 0")
    vary = _parse_vary(args.vary)
    for line in _prepare_source(args):
        print(f"  [warning] {line}")
    fixed = _parse_set(args.set)
    for name, text in _program_value(args).items():     # the program: one value every variant runs
        if name in vary or name in fixed:
            raise NcfmuError(f"--program and --vary/--set {name}=... both give {name}: give one")
        fixed[name] = text
    # Ctrl-C or SIGTERM: serially, between chunks of steps (the FMUs run in this process); on dask at once (this
    # process only waits for its workers). Either way the summary is written, the cluster closed, one line said.
    serial = args.workers == 0 and args.scheduler is None and args.scheduler_file is None
    try:
        with deferred_interrupts() if serial else raised_interrupts():
            rows = sweep(args.system, vary, Path(args.out), workers=args.workers, scheduler=args.scheduler,
                         scheduler_file=args.scheduler_file, stop_time=args.stop_time, root=args.root,
                         record=args.record, output_interval=args.output_interval, timeout=args.timeout,
                         connect_timeout=args.connect_timeout, fixed=fixed)
    except Interrupted as err:
        how, status = stopped_by(err)
        if isinstance(err, SweepStopped) and err.summary.is_file():
            print(f"ncfmu sweep: {how}: {err.done} of {err.total} variants done, in {err.summary}; the same "
                  "command runs the rest", file=sys.stderr)
        elif isinstance(err, SweepStopped):     # nothing written yet: no summary to name
            print(f"ncfmu sweep: {how}: {err.done} of {err.total} variants done; the same command runs them",
                  file=sys.stderr)
        else:                       # while the system was built or read: before any variant ran
            print(f"ncfmu sweep: {how} before any variant ran; the same command runs them", file=sys.stderr)
        raise SystemExit(status) from None
    counts = {s: sum(r["status"] == s for r in rows) for s in STATUSES}
    print(f"{args.system}: {len(rows)} variants, " + ", ".join(f"{n} {s}" for s, n in counts.items())
          + f" -> {Path(args.out) / 'summary.csv'}")
    for r in rows:
        if r["status"] != "ok":
            varied = ", ".join(f"{k}={r[k]}" for k in vary)
            print(f"  {r['status']}: {varied}: {r['error']}")
    for line in _unreached_lines(args.system, [{**fixed, **dict(zip(vary, values))}
                                               for values in itertools.product(*vary.values())],
                                 dict.fromkeys(vary, "--vary")):
        print(line)
    return sweep_exit_status([str(r["status"]) for r in rows])


def sweep_exit_status(statuses: list[str]) -> int:
    """A sweep's exit status from its variants' statuses, as ``ncfmu run``'s: a part rejected (a crash, out of
    tolerance) in any variant is EXIT_PART_REJECTED, else any variant not done (unfinished, failed, timed out)
    EXIT_NOT_FINISHED, else EXIT_OK."""
    from .exitcodes import EXIT_PART_REJECTED
    from .systems.outcome import EXIT_OF
    exits = {EXIT_OF[s] for s in statuses}
    return next((e for e in (EXIT_PART_REJECTED, EXIT_NOT_FINISHED) if e in exits), EXIT_OK)


def cmd_plot(args) -> int:
    from . import plots
    src = Path(args.file)
    if not src.is_file():
        raise NcfmuError(f"{src}: no such file (give a result CSV from 'ncfmu run' or a sweep's summary.csv)")
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise NcfmuError("plotting needs matplotlib: pip install -e '.[plot]'") from None
    out = Path(args.png) if args.png else src.with_suffix(".png")
    if out.is_dir():
        raise NcfmuError(f"--png {out}: is a folder; give the PNG file's name")
    if out.suffix.lower() != ".png":
        raise NcfmuError(f"--png {out}: must end in .png (the plot is a PNG image)")
    with open(src, encoding="utf-8-sig", errors="replace") as f:
        header = f.readline()
    # a sweep's summary by its columns (a status per variant), not by its file name alone
    if "status" in (cell.strip().strip('"') for cell in header.split(",")):
        print(plots.plot_sweep(src, out))
    else:
        from .systems import SYSTEMS, report_for
        if args.system is not None and args.system not in SYSTEMS:
            raise NcfmuError(f"--system {args.system!r}: unknown; one of {', '.join(SYSTEMS)} (or leave it out to "
                             "draw the CSV's signals over time)")
        result = plots.read_plot_csv(src)       # streamed, decimated: a CSV of any length in bounded memory
        name = args.system or src.stem.split("_branch")[0]
        # a known system's plot when the CSV names it (--system, or the file name with that system's axes in it);
        # else, e.g. a single FMU's CSV from fmpy, every recorded signal over time
        if name in SYSTEMS and (args.system or any(f"{a}.pos" in result for a in report_for(name).axes)):
            missing = [q for q in report_for(name).record() if q not in result]
            if args.system and len(missing) == len(report_for(name).record()):
                raise NcfmuError(f"{src}: has none of the signals a {name} plot draws ({', '.join(missing[:4])}, ...): "
                                 "not a result of that system (leave --system out to draw the CSV's own signals)")
            result.system = name
            result.parameters = _read_run_record(src, name) or {}      # else the system's own parameter sets
            print(plots.plot_result(result, out))
        else:
            result.system = src.stem
            print(plots.plot_signals(result, out))
    return 0


def cmd_vars(args) -> int:
    """Every parameter, input and output of a system: kind, type, unit, the system's start value, rule, what drives
    an input or what an output feeds."""
    from dataclasses import replace

    from .cosim.ssp import read_ssp
    from .project import OpenSystem, model_descriptions
    from .systems import get_system
    from .systems.settable import settable
    warnings: list[str] = _prepare_source(args)
    foreign: list[str] = []
    if args.system.endswith(".ssp"):
        archive = Path(args.system)
        system = read_ssp(archive)
        described = model_descriptions(archive, system)
        rows = settable(system, described.__getitem__, outputs=True)
        # the system opened as a run opens it: what a run refuses, vars refuses; the conversions and warnings
        with OpenSystem(archive) as opened:
            conversions = opened.master.conversions
            warnings = [*warnings, *opened.warnings()]
            foreign = [f"{inst}: {identity}" for inst, identity in opened.identities.items() if not identity.model]
        rows = [replace(r, driven_by=f"{r.driven_by} ({conversions[key]})")
                if (key := tuple(r.name.split(".", 1))) in conversions else r for r in rows]
    else:
        system = get_system(args.system)
        rows = settable(system, outputs=True)
    if args.instance:
        known = [c.name for c in system.components]
        if args.instance not in known:
            raise NcfmuError(f"--instance {args.instance!r}: {system.name} has no such instance "
                             f"(instances: {', '.join(known)})")
        rows = [r for r in rows if r.name.split(".", 1)[0] == args.instance]
    n_out = sum(r.kind == "output" for r in rows)
    lines = [f"{system.name}: {len(rows) - n_out} parameters and inputs, {n_out} outputs. Set one with --set "
             "INSTANCE.VARIABLE=VALUE (ncfmu run); tunable parameters and free inputs also with --branch-set, free "
             "inputs with --input FILE.csv. An input a connection drives cannot be set: set its source. START is the "
             "system's value; a parameter marked unused is one the system's values leave unread (setting it changes "
             "nothing). Outputs are what --record takes and an OPC UA client reads."]
    header = ("NAME", "KIND", "TYPE", "UNIT", "START", "RULE", "DRIVEN BY", "DESCRIPTION")
    long = 30                        # a longer start value (a program) goes on a line of its own, below
    table = [(r.name, r.kind, r.type, r.unit, r.start if len(r.start) <= long else "(below)", r.rule,
              r.driven_by or "-", r.description) for r in rows]
    widths = [max(len(row[i]) for row in [header, *table]) for i in range(len(header) - 1)]
    for r, row in zip([None, *rows], [header, *table]):
        lines.append("  ".join(cell.ljust(w) for cell, w in zip(row, widths)) + "  " + row[-1])
        if r is not None and len(r.start) > long:
            lines.append(f"    start: {r.start}")
    lines += [f"  foreign FMU {line}" for line in foreign]
    lines += [f"  [warning] {w}" for w in warnings]
    try:
        sys.stdout.write("\n".join(lines) + "\n")
        sys.stdout.flush()
    except BrokenPipeError:          # `ncfmu vars SYSTEM | head`: the reader has all it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


def cmd_serve(args) -> int:
    from .serving import APPLICATION_URI, Security, make_certificate, serve
    if args.make_certificate is not None:
        key, cert = make_certificate(args.make_certificate)
        print(f"ncfmu serve: wrote {cert} (application URI {APPLICATION_URI}) and its private key {key}; serve "
              f"with --certificate {cert} --private-key {key}; clients trust {cert}")
        return 0
    users = {}
    for item in args.user or []:
        name, colon, password = item.partition(":")
        if not colon or not name or not password:
            raise NcfmuError(f"--user {item!r}: expected NAME:PASSWORD")
        users[name] = password
    if args.speed is not None and not (args.speed >= 0 and args.speed < float("inf")):
        raise NcfmuError(f"--speed {args.speed!r}: must be a number >= 0 (0: as fast as possible)")
    if args.record and not args.out:
        raise NcfmuError("--record needs --out DIR (where the recorded trajectory is written)")
    if args.on_lost is not None and args.watchdog is None:
        raise NcfmuError(f"--on-lost {args.on_lost}: needs --watchdog S (what tells that a client is lost)")

    def ready(endpoint: str) -> None:
        print(f"ncfmu serve: {args.system} at {endpoint} (speed {args.speed:g}); Ctrl-C stops", flush=True)

    def verdict(t: float, line: str) -> None:
        print(f"ncfmu serve: program ended at t = {t:.3f} s: {line}", flush=True)

    security = Security(users, args.certificate, args.private_key, args.trust, args.allow_insecure)
    front = None
    if args.web is not None:            # the live page beside the OPC UA server (ncfmu.web)
        from .web import WebFront, check_address, parse_address
        address = parse_address(args.web)
        check_address(address, security)

        def front(live, watch) -> WebFront:
            return WebFront(live, address, security, watch,
                            listening=lambda url: print(f"ncfmu serve: the live page at {url}", flush=True))

    program = _program_value(args)
    summary = serve(args.system, endpoint=args.endpoint, speed=args.speed,
                    start_values={**_parse_set(args.set), **program},
                    stop_time=args.stop_time, step_size=args.step, record=args.record, out=args.out,
                    security=security,
                    root=args.root, ready=ready,
                    watchdog=args.watchdog, cnc=args.cnc, on_lost=args.on_lost or "hold",
                    on_verdict=verdict, drawing=_drawing(args), front=front)
    print(f"ncfmu serve: {summary.system} {summary.state} at t = {summary.time:.3f} s"
          + (f" ({summary.reason})" if summary.reason else "")
          + f" after {summary.wall:.2f} s of wall time"
          + f"; lag p50 {summary.lag_p50 * 1e3:.2f} ms, p99 {summary.lag_p99 * 1e3:.2f} ms, "
            f"max {summary.lag_max * 1e3:.2f} ms; overruns {summary.overruns}; {len(summary.writes)} writes",
          flush=True)
    for path in summary.files:
        print(f"  written: {path}")
    return EXIT_PROBLEMS if summary.state == "failed" else EXIT_OK


def cmd_validate(args) -> int:
    from .project import validation
    checked = validation(args.root)
    print("checked " + ";\nchecked ".join(checked.checked()))
    for p in checked.problems:
        print(p)
    print("all FMUs and SSPs valid" if not checked.problems else f"{len(checked.problems)} problem(s)")
    return EXIT_PROBLEMS if checked.problems else EXIT_OK


def main(argv: list[str] | None = None) -> int:
    from .cosim.algorithm import MODES
    from .systems.outcome import RUN_LIMIT
    stop_time_help = (f"the limit of simulated time, s: a system with a done signal stops where its work ends "
                      f"(default limit {RUN_LIMIT:g} s); one without (a bare FMU) runs to it (default: the system's "
                      "stop time)")
    help_epilog = epilog()
    parser = _Parser(prog="ncfmu", description="Classic NC controllers as FMI 2.0 co-simulation FMUs, "
                     "run closed loop with servo axes.", epilog=help_epilog)
    parser.add_argument("--root", type=Path, default=None, help="project folder (with models/, fmus/, ssp/)")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("build", help="build every FMU into fmus/ and pack every system into ssp/<system>.ssp")
    p.add_argument("--force", action="store_true", help="rebuild FMUs even when they are up to date")
    p.add_argument("--pure", action="store_true",
                   help="ship the controllers as Python sources only (no mypyc compile; else compiled once per "
                        "source change, cached in ~/.cache/ncfmu/compiled/). The kind is recorded in fmus/ and "
                        "kept by later run, sweep, serve and validate until 'ncfmu build' without --pure or "
                        "--compiled switches back")
    p.set_defaults(func=cmd_build)

    p = sub.add_parser("run", help="simulate a system closed loop and print a summary",
                       description="Simulate a system closed loop until its work is done (the program's M30/M02, "
                                   "the registers' last pass, the grinder's return, the contour's end: the last row "
                                   "within a second of it), a crash of the part check or an alarm halts the "
                                   "machine, or the --stop-time limit; print a summary. " + EXIT_HELP,
                       epilog=help_epilog)
    p.add_argument("system", nargs="?", default="lathe_roughing", help="system name or path of an .ssp file")
    p.add_argument("--stop-time", type=_real_option, default=None, help=stop_time_help)
    p.add_argument("--step", type=_real_option, default=None, help="communication step in s (default 0.001)")
    p.add_argument("--set", action="append", metavar="INSTANCE.VAR=VALUE",
                   help="start value or parameter, e.g. --set seq.block[1].Xd=0.4 (repeatable)")
    p.add_argument("--input", type=Path, default=None, help="CSV of input changes (columns time, INSTANCE.VARIABLE)")
    p.add_argument("--mode", choices=MODES, default=MODES[0], help="master algorithm")
    p.add_argument("--out", default="out", help="folder for SYSTEM.csv (default: out); the rows are streamed to "
                   "SYSTEM.csv.partial and renamed when the run completed (an interrupted run leaves the .partial: "
                   "a valid CSV of every row up to where it stopped); a completed run also writes "
                   "SYSTEM.run.json, the parameters it applied, which 'ncfmu plot' reads")
    p.add_argument("--record", nargs="+", default=None, metavar="NAME",
                   help="outputs written to SYSTEM.csv, INSTANCE.VARIABLE (default: every output)")
    p.add_argument("--output-interval", type=_real_option, default=None, metavar="S",
                   help="write a row every S seconds of simulated time (a whole multiple of the step; default: "
                        "every step)")
    p.add_argument("--plot", action="store_true", help="also write SYSTEM.png (drawn from every step, decimated to "
                   "what the figure shows: every extreme and edge kept, in bounded memory)")
    p.add_argument("--tolerance", type=_real_option, default=None, metavar="MM",
                   help="the part check's tolerance of the part made against the programmed part, mm (default "
                        "0.01); exit status 3 on a crash or a part out of tolerance")
    p.add_argument("--nose-radius", type=_real_option, default=None, metavar="MM",
                   help="the lathe tools' nose radius for the part check, every tool's, mm (default: each tool's "
                        "seq.tool[k].nose_radius, the row its T word names, else 0: a sharp corner)")
    p.add_argument("--max-depth", type=_real_option, default=None, metavar="MM",
                   help="the deepest cut (radial engagement) the lathe tool may take, mm (default: the tool "
                        "table's seq.tool[k].max_depth, else no limit)")
    p.add_argument("--no-part-check", action="store_true",
                   help="no material removal, crash and tolerance check (and no SYSTEM.part.json)")
    p.add_argument("--drawing", type=Path, default=None, metavar="FILE.dxf",
                   help="judge the part made against the part drawn, in place of the programmed part (also for "
                        "programs without G71/G70): a DXF of LINE, ARC, CIRCLE, LWPOLYLINE in mm; a lathe's upper "
                        "half section (drawing X = machine Z, Y = radius), a mill's outline in XY")
    p.add_argument("--branch-at", type=_real_option, default=None, metavar="T",
                   help="simulate to T once, save every FMU's state, then run one branch per --branch-set value")
    p.add_argument("--branch-set", action="append", metavar="INSTANCE.VAR=V1,V2,...",
                   help="tunable parameter or input set at the branch point, one value per branch, "
                        "e.g. --branch-set panel.emergency_at=12,21,31")
    _replace_options(p)
    _program_option(p)
    _kind_options(p)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("sweep", help="run the cartesian product of parameter values on dask.distributed",
                       description="Run every combination of the --vary values on dask workers (they need ncfmu "
                                   "installed, nothing else: the system is shipped to them, results come back). "
                                   "The client writes OUT/variants/<key>.csv and a row of OUT/summary.csv (status "
                                   "ok/crashed/out_of_tolerance/unfinished/failed/timeout, error, wall time, "
                                   "metrics), atomically. Each variant runs as 'ncfmu run' runs: until its work is "
                                   "done, a crash or an alarm, --stop-time the limit; 'unfinished': the limit "
                                   "reached with the cycle not finished (error 'cycle not finished by t = ...'), an "
                                   "alarm, or the part not judged. A sweep into an existing OUT merges into it; "
                                   "variants already done are not run again. Exit status 0 when every variant is "
                                   "ok, 3 when any crashed or is out of tolerance, else 4 when any is unfinished, "
                                   "failed or timed out, 2 for a bad command line.",
                       epilog="example: ncfmu sweep lathe_roughing --vary seq.block[1].Xd=0.4,0.5,0.6 --workers 2 "
                              "--out sweep_xd")
    p.add_argument("system", help="system name or path of an .ssp file")
    p.add_argument("--vary", action="append", required=True, metavar="INSTANCE.VAR=V1,V2,...",
                   help="values of one parameter (repeat for more: the product is run)")
    p.add_argument("--set", action="append", metavar="INSTANCE.VAR=VALUE",
                   help="a start value or parameter every variant shares, e.g. --set seq.program=\"...\" "
                        "(repeatable)")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--workers", type=_integer_option, default=2,
                       help="worker processes of a local dask cluster (default 2; 0: serial, no dask)")
    group.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="address of a running dask scheduler, e.g. tcp://127.0.0.1:8786")
    group.add_argument("--scheduler-file", default=None, metavar="FILE",
                       help="the scheduler file of a running dask scheduler (dask scheduler --scheduler-file FILE)")
    p.add_argument("--stop-time", type=_real_option, default=None, help=stop_time_help)
    p.add_argument("--out", required=True, help="folder for summary.csv and variants/")
    p.add_argument("--record", nargs="+", default=None, metavar="NAME",
                   help="outputs kept per variant, INSTANCE.VARIABLE (default: the axes' positions and what the "
                        "summary metrics read)")
    p.add_argument("--output-interval", type=_real_option, default=None, metavar="S",
                   help="keep every S seconds of the trajectories (a whole multiple of the system's step)")
    p.add_argument("--timeout", type=_real_option, default=None, metavar="S",
                   help="wall-clock seconds a variant may take; over it the variant is recorded as 'timeout'")
    p.add_argument("--connect-timeout", type=_real_option, default=5.0, metavar="S",
                   help="seconds to wait for --scheduler or --scheduler-file to answer and have a worker (default 5)")
    _replace_options(p)
    _program_option(p)
    _kind_options(p)
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser("plot", help="plot a result CSV (positions, errors, path with envelope) or a sweep summary.csv",
                       description="A known system's CSV gets its plot (positions, following errors, the path with "
                                   "its envelope or contour), with the parameters of its run from SYSTEM.run.json "
                                   "beside it when 'ncfmu run' left one there (a part program's profile, --set "
                                   "values), else the system's own; any other result CSV in fmpy's layout (a single "
                                   "FMU run by fmpy, another tool's) its recorded signals over time.")
    p.add_argument("file", help="OUT/SYSTEM.csv from 'ncfmu run', a CSV fmpy wrote, or OUT/summary.csv from "
                                "'ncfmu sweep'")
    p.add_argument("--system", default=None, help="system the CSV came from (default: from the file name; a CSV "
                                                  "that names none is drawn as signals over time)")
    p.add_argument("--png", default=None, help="output file (default: the CSV's name with .png)")
    p.set_defaults(func=cmd_plot)

    p = sub.add_parser("vars", help="list every parameter and input of a system: unit, start value, rule, "
                       "description, tunable or fixed, the connection that drives an input; and its outputs",
                       description="Every settable variable of a system (what --set, --branch-set, --vary and "
                                   "--input take): kind (parameter tunable/fixed, unused where the system's values "
                                   "leave it unread, input), type, unit, the start value the system gives it, its "
                                   "rule, the output a connection drives an input from, and its description; then "
                                   "each instance's outputs (what --record takes) with unit, description and what "
                                   "they feed.", epilog=help_epilog)
    p.add_argument("system", help="system name or path of an .ssp file")
    p.add_argument("--instance", default=None, help="only this instance, e.g. panel")
    _replace_options(p)
    p.set_defaults(func=cmd_vars)

    p = sub.add_parser("serve", help="run a system in real time behind an OPC UA server (virtual commissioning)",
                       description="Run the system with simulated time paced to the wall clock behind an OPC UA "
                                   "server: clients read every variable (ns urn:ncfmu:SYSTEM, NodeId "
                                   "INSTANCE.VARIABLE), force inputs, set tunable parameters, and Pause/Resume/"
                                   "Stop/Reset the Simulation object. Stops on Ctrl-C, SIGTERM, Stop or the stop "
                                   "time, writes what it recorded and exits 0.", epilog=help_epilog)
    p.add_argument("system", nargs="?", default="lathe_roughing", help="system name or path of an .ssp file")
    p.add_argument("--set", action="append", metavar="INSTANCE.VAR=VALUE", help="start value or parameter")
    p.add_argument("--endpoint", default="opc.tcp://127.0.0.1:4840/ncfmu",
                   help="where the server listens (default opc.tcp://127.0.0.1:4840/ncfmu; another address than "
                        "the loopback needs --user)")
    p.add_argument("--speed", type=_real_option, default=1.0,
                   help="simulated seconds per wall-clock second (default 1; 0: as fast as possible)")
    p.add_argument("--stop-time", type=_real_option, default=None, help="stop at this simulated time (default: never)")
    p.add_argument("--step", type=_real_option, default=None, help="communication step in s (default: the system's)")
    p.add_argument("--record", nargs="+", default=None, metavar="NAME",
                   help="outputs recorded, INSTANCE.VARIABLE (default: every output); needs --out")
    p.add_argument("--out", default=None, help="folder for SYSTEM.csv and session_inputs.csv (the writes, "
                                               "replayable with 'ncfmu run --input')")
    p.add_argument("--user", action="append", metavar="NAME:PASSWORD",
                   help="a user who may connect (then only users connect; required off the loopback)")
    p.add_argument("--certificate", type=Path, default=None,
                   help="server certificate: adds the Basic256Sha256 SignAndEncrypt policy (with --private-key)")
    p.add_argument("--private-key", type=Path, default=None, help="the certificate's private key")
    p.add_argument("--trust", type=Path, default=None, metavar="DIR",
                   help="folder of the client certificates (or their CAs' certificates) accepted; any other is "
                        "refused (needs --certificate; required off the loopback)")
    p.add_argument("--allow-insecure", action="store_true",
                   help="off the loopback, also security policy None and any client certificate (a closed network)")
    p.add_argument("--make-certificate", type=Path, default=None, metavar="DIR",
                   help="write DIR/ncfmu.der (a self-signed certificate with ncfmu's application URI) and "
                        "DIR/ncfmu-key.pem, then exit")
    p.add_argument("--cnc", action=argparse.BooleanOptionalAction, default=True,
                   help="also serve the system as OPC UA for CNC Systems (OPC 40502): Objects/CncInterface with "
                        "its CncAxisList, CncChannelList and CncSpindleList (the default; about 1 s more to start, "
                        "--no-cnc leaves it out)")
    p.add_argument("--watchdog", type=_real_option, default=None, metavar="S",
                   help="a client session that forced inputs is lost when it closes or sends nothing for S "
                        "seconds: see --on-lost (logged)")
    p.add_argument("--on-lost", choices=("hold", "release"), default=None,
                   help="with --watchdog, what a lost client leaves: hold (default) -- the machine goes to feed "
                        "hold (each feed_hold input forced true; without one the simulation halts), its forces "
                        "kept, Simulation.state 'held' and Simulation.reason why, until a client calls "
                        "Simulation.Resume; release -- its forces fall back to what drives them at once "
                        "(recorded as releases)")
    p.add_argument("--drawing", type=Path, default=None, metavar="FILE.dxf",
                   help="the part check judges against the part drawn (as 'ncfmu run --drawing'): a served mill's "
                        "gouges are crashes against the outline drawn")
    p.add_argument("--web", nargs="?", const="127.0.0.1:8080", default=None, metavar="HOST:PORT",
                   help="also serve the live page of the machine there (default 127.0.0.1:8080; another address "
                        "than the loopback needs --user and --certificate, or --allow-insecure)")
    _program_option(p)
    _kind_options(p)
    p.set_defaults(func=cmd_serve, no_part_check=False)

    p = sub.add_parser("pack", help="write a system (an .ssd with its folder, an unpacked folder, an .ssp or a bare "
                       ".fmu; components replaced with --replace) as one .ssp archive")
    p.add_argument("system", help="system name, .ssp, .ssd, unpacked system folder or .fmu")
    p.add_argument("--output", "-o", required=True, help="the .ssp file to write")
    _replace_options(p)
    p.set_defaults(func=cmd_pack)

    p = sub.add_parser("validate", help="validate every FMU (fmpy) and SSP (SSP 1.0 schema) and list problems")
    p.set_defaults(func=cmd_validate)

    args, unknown = parser.parse_known_args(_negative_values(sys.argv[1:] if argv is None else argv))
    if unknown:                      # named by the command they were given to, not by the top-level parser
        parser.exit(2, f"ncfmu {args.command}: unrecognized arguments: {' '.join(unknown)}\n")
    try:
        _check_positive(args)
        if args.command in ("run", "sweep"):
            _output_folder(args.out)
        _build_kind(args)
        return args.func(args)
    except KeyboardInterrupt as err:  # before a command's own handling began (imports, its options, a build)
        from .cosim.interrupts import stopped_by
        how, status = stopped_by(err)
        print(f"ncfmu {args.command}: {how}", file=sys.stderr)
        return status
    except FmuCrashed as err:        # a foreign FMU's process died (a branch run, an instantiation): not finished
        print(f"ncfmu {args.command}: {err}", file=sys.stderr)
        return EXIT_NOT_FINISHED
    except NcfmuError as err:
        print(f"ncfmu {args.command}: {_in_words(err)}", file=sys.stderr)
        return EXIT_REFUSED
    except OSError as err:           # the machine's refusal (a full disk, a folder that went away): one line too
        print(f"ncfmu {args.command}: {err}", file=sys.stderr)
        return EXIT_REFUSED


if __name__ == "__main__":
    sys.exit(main())
