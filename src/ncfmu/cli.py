"""The ``ncfmu`` command: build, run, validate."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from .errors import NcfmuError

EPILOG = ("Systems: lathe_roughing (default), lathe_taper, grinder_feed, grinder_envelope, mill_contour. "
          "Instances: lathe panel, seq, limiter, x_axis, z_axis; grinder panel, feed, limiter, x_axis, y_axis; "
          "mill panel, contour, x_axis, y_axis.")


def _parse_set(items: list[str]) -> dict[str, object]:
    values: dict[str, object] = {}
    for item in items or []:
        name, eq, raw = item.partition("=")
        if not eq or "." not in name:
            raise NcfmuError(f"--set {item!r}: expected INSTANCE.VARIABLE=VALUE, e.g. seq.block[1].Xd=0.4")
        low = raw.strip().lower()
        if low in ("true", "false"):
            values[name] = low == "true"
        else:
            try:
                values[name] = int(raw) if raw.strip().lstrip("+-").isdigit() else float(raw)
            except ValueError:
                values[name] = raw
    return values


def _summary(result, report_lines: list[str] | None = None) -> str:
    """The run's summary: the report's lines from its trajectory, or ``report_lines`` computed as it ran."""
    from .systems import report_of, run_parameters
    lines = [f"system {result.system}: simulated {result.end_time:.3f} s in {result.wall_time:.2f} s wall "
             f"(simulated/wall-clock ratio {result.realtime_factor:.1f})"]
    lines += (report_of(result).summary(result, run_parameters(result)) if report_lines is None
              else report_lines)
    for _inst, msgs in result.messages.items():
        for level, text in msgs:
            if level in ("warning", "error", "fatal"):
                lines.append(f"  [{level}] {text}")
    return "\n".join(lines)


def cmd_build(args) -> int:
    from .project import build
    out = build(args.root, only_stale=not args.force)
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


def _run_streamed(args, start_values: dict[str, object]):
    """Run with the rows streamed to ``OUT/SYSTEM.csv`` (through ``SYSTEM.csv.partial``, renamed when the run
    completed) and the summary computed as the run goes; only ``--plot`` keeps the trajectory in memory.
    Prints the summary; returns the result and where its CSV is."""
    import signal

    from .cosim.master import Interrupted, deferred_interrupts, steps_per_row
    from .cosim.record import CsvSink, EveryKth, RecordSink, SelectColumns
    from .cosim.ssp import read_ssp
    from .project import simulate, system_archive
    from .systems import report_for
    archive = system_archive(args.system, args.root)
    system = read_ssp(archive)
    report = report_for(system.name, {c.name: c.model for c in system.components})
    parameters: dict[str, dict[str, object]] = {c.name: dict(c.parameters) for c in system.components}
    for qualified, value in start_values.items():
        inst, _, var = qualified.partition(".")
        parameters.setdefault(inst, {})[var] = value
    record = None if args.record is None else list(dict.fromkeys(args.record))
    csv_sink = CsvSink(Path(args.out) / f"{system.name}.csv")
    accumulator = None
    sinks: list[RecordSink]
    interval = args.output_interval
    if args.plot:                       # the plot needs the whole trajectory: kept in memory
        sinks, run_record = [csv_sink], record
    else:
        # the summary reads every step; the CSV gets the --record columns at the --output-interval
        accumulator = _Summary(report, parameters)
        run_record = None if record is None else list(dict.fromkeys([*record, *report.record()]))
        csv_view: RecordSink = csv_sink if run_record == record else SelectColumns(csv_sink, record or [])
        every = steps_per_row(interval, system.step_size if args.step is None else args.step)
        sinks = [csv_view if every == 1 else EveryKth(csv_view, every), accumulator]
        interval = None
    try:
        with deferred_interrupts():
            result = simulate(str(archive), stop_time=args.stop_time, step_size=args.step,
                              start_values=start_values, input_csv=args.input, mode=args.mode, root=args.root,
                              record=run_record, output_interval=interval, sinks=sinks, keep=args.plot)
    except KeyboardInterrupt as err:
        terminated = isinstance(err, Interrupted) and err.signum == signal.SIGTERM
        print(f"ncfmu run: {'terminated (SIGTERM)' if terminated else 'interrupted'}: {_where_stopped(csv_sink)}",
              file=sys.stderr)
        raise SystemExit(143 if terminated else 130) from None
    except NcfmuError as err:
        if csv_sink.final_path is None:
            raise
        raise NcfmuError(f"{err} ({_where_stopped(csv_sink)})") from None
    result.system = system.name
    print(_summary(result, None if accumulator is None else accumulator.summary()))
    return result, csv_sink.final_path


class _Summary:
    """The report's accumulator, made when the run opens its sinks: after the master checked every --set."""

    def __init__(self, report, parameters: dict[str, dict[str, object]]) -> None:
        self.report, self.parameters = report, parameters
        self.accumulator: Any = None

    def open(self, columns) -> None:
        self.accumulator = self.report.accumulator(self.parameters)
        self.accumulator.open(columns)

    def write(self, rows) -> None:
        assert self.accumulator is not None
        self.accumulator.write(rows)

    def close(self, complete: bool, stopped_at: float | None = None, reason: str = "") -> None:
        if self.accumulator is not None:
            self.accumulator.close(complete, stopped_at, reason)

    def summary(self) -> list[str]:
        assert self.accumulator is not None
        return self.accumulator.summary()


def _where_stopped(sink) -> str:
    if not sink.rows:
        return f"no rows recorded ({sink.final_path} has the header only)"
    return f"{sink.rows} rows up to t = {sink.stopped_at:.3f} s in {sink.final_path} (the run did not finish)"


def cmd_run(args) -> int:
    from .project import simulate_branches
    if args.branch_at is not None:
        if args.input:
            raise NcfmuError("--input and --branch-at together: branches start from a saved state and take no input "
                             "CSV; run the input without --branch-at, or branch with --branch-set")
        variants = _parse_branches(args.branch_set)
        results = simulate_branches(args.system, args.branch_at, variants, stop_time=args.stop_time,
                                    start_values=_parse_set(args.set), mode=args.mode, root=args.root)
        out = Path(args.out)
        for i, (variant, result) in enumerate(zip(variants, results)):
            csv = result.to_csv(out / f"{result.system}_branch{i}.csv")
            label = ", ".join(f"{k}={v}" for k, v in variant.items()) or "no change"
            print(f"branch {i} from t = {args.branch_at} s ({label}):")
            print(_summary(result))
            print(f"  results: {csv}")
        return 0
    start_values = _parse_set(args.set)
    if args.output_interval is not None and not (args.output_interval > 0 and args.output_interval < float("inf")):
        raise NcfmuError(f"--output-interval {args.output_interval!r}: must be a number of seconds > 0")
    result, csv = _run_streamed(args, start_values)
    out = Path(args.out)
    print(f"  results: {csv}")
    if args.plot:
        try:
            import matplotlib  # noqa: F401

            from .plots import plot_result
        except ImportError:
            raise NcfmuError("--plot needs matplotlib: pip install -e '.[plot]'") from None
        print(f"  plot: {plot_result(result, out / f'{result.system}.png')}")
    return 0


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
    from .batch import sweep
    for name, value in (("--timeout", args.timeout), ("--output-interval", args.output_interval),
                        ("--stop-time", args.stop_time)):
        if value is not None and not (value > 0 and value < float("inf")):
            raise NcfmuError(f"{name} {value!r}: must be a number > 0")
    vary = _parse_vary(args.vary)
    rows = sweep(args.system, vary, Path(args.out), workers=args.workers, scheduler=args.scheduler,
                 scheduler_file=args.scheduler_file, stop_time=args.stop_time, root=args.root, record=args.record,
                 output_interval=args.output_interval, timeout=args.timeout)
    counts = {s: sum(r["status"] == s for r in rows) for s in ("ok", "failed", "timeout")}
    print(f"{args.system}: {len(rows)} variants, {counts['ok']} ok, {counts['failed']} failed, "
          f"{counts['timeout']} timeout -> {Path(args.out) / 'summary.csv'}")
    for r in rows:
        if r["status"] != "ok":
            varied = ", ".join(f"{k}={r[k]}" for k in vary)
            print(f"  {r['status']}: {varied}: {r['error']}")
    return 0


def cmd_plot(args) -> int:
    from .cosim.result import Result
    from .plots import plot_result, plot_sweep
    src = Path(args.file)
    if not src.is_file():
        raise NcfmuError(f"{src}: no such file (give a result CSV from 'ncfmu run' or a sweep's summary.csv)")
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise NcfmuError("plotting needs matplotlib: pip install -e '.[plot]'") from None
    out = Path(args.png) if args.png else src.with_suffix(".png")
    if src.name == "summary.csv":
        print(plot_sweep(src, out))
    else:
        from .systems import SYSTEMS
        result = Result.from_csv(src)
        result.system = args.system or src.stem.split("_branch")[0]
        if result.system not in SYSTEMS:
            raise NcfmuError(f"{src}: system {result.system!r} unknown (from the file name); give the system the "
                             f"CSV came from with --system, one of {', '.join(SYSTEMS)}")
        print(plot_result(result, out))
    return 0


def cmd_serve(args) -> int:
    from .serving import Security, serve
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

    def ready(endpoint: str) -> None:
        print(f"ncfmu serve: {args.system} at {endpoint} (speed {args.speed:g}); Ctrl-C stops", flush=True)

    summary = serve(args.system, endpoint=args.endpoint, speed=args.speed, start_values=_parse_set(args.set),
                    stop_time=args.stop_time, step_size=args.step, record=args.record, out=args.out,
                    security=Security(users, args.certificate, args.private_key), root=args.root, ready=ready)
    print(f"ncfmu serve: {summary.system} {summary.state} at t = {summary.time:.3f} s"
          + (f" ({summary.reason})" if summary.reason else "")
          + f" after {summary.wall:.2f} s of wall time"
          + f"; lag p50 {summary.lag_p50 * 1e3:.2f} ms, p99 {summary.lag_p99 * 1e3:.2f} ms, "
            f"max {summary.lag_max * 1e3:.2f} ms; overruns {summary.overruns}; {len(summary.writes)} writes",
          flush=True)
    for path in summary.files:
        print(f"  written: {path}")
    return 1 if summary.state == "failed" else 0


def cmd_validate(args) -> int:
    from .project import validate
    problems = validate(args.root)
    for p in problems:
        print(p)
    print("all FMUs and SSPs valid" if not problems else f"{len(problems)} problem(s)")
    return 1 if problems else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ncfmu", description="Classic NC controllers as FMI 2.0 co-simulation FMUs, "
                                     "run closed loop with servo axes.", epilog=EPILOG)
    parser.add_argument("--root", type=Path, default=None, help="project folder (with models/, fmus/, ssp/)")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("build", help="build every FMU into fmus/ and pack every system into ssp/<system>.ssp")
    p.add_argument("--force", action="store_true", help="rebuild FMUs even when they are up to date")
    p.set_defaults(func=cmd_build)

    p = sub.add_parser("run", help="simulate a system closed loop and print a summary", epilog=EPILOG)
    p.add_argument("system", nargs="?", default="lathe_roughing", help="system name or path of an .ssp file")
    p.add_argument("--stop-time", type=float, default=None, help="stop time in s (default: the system's)")
    p.add_argument("--step", type=float, default=None, help="communication step in s (default 0.001)")
    p.add_argument("--set", action="append", metavar="INSTANCE.VAR=VALUE",
                   help="start value or parameter, e.g. --set seq.block[1].Xd=0.4 (repeatable)")
    p.add_argument("--input", type=Path, default=None, help="CSV of input changes (columns time, INSTANCE.VARIABLE)")
    p.add_argument("--mode", choices=("gauss-seidel", "jacobi"), default="gauss-seidel", help="master algorithm")
    p.add_argument("--out", default="out", help="folder for SYSTEM.csv (default: out); the rows are streamed to "
                   "SYSTEM.csv.partial and renamed when the run completed (an interrupted run leaves the .partial: "
                   "a valid CSV of every row up to where it stopped)")
    p.add_argument("--record", nargs="+", default=None, metavar="NAME",
                   help="outputs written to SYSTEM.csv, INSTANCE.VARIABLE (default: every output)")
    p.add_argument("--output-interval", type=float, default=None, metavar="S",
                   help="write a row every S seconds of simulated time (a whole multiple of the step; default: "
                        "every step)")
    p.add_argument("--plot", action="store_true", help="also write SYSTEM.png (keeps the trajectory in memory)")
    p.add_argument("--branch-at", type=float, default=None, metavar="T",
                   help="simulate to T once, save every FMU's state, then run one branch per --branch-set value")
    p.add_argument("--branch-set", action="append", metavar="INSTANCE.VAR=V1,V2,...",
                   help="tunable parameter or input set at the branch point, one value per branch, "
                        "e.g. --branch-set panel.emergency_at=12,21,31")
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("sweep", help="run the cartesian product of parameter values on dask.distributed",
                       description="Run every combination of the --vary values on dask workers (they need ncfmu "
                                   "installed, nothing else: the system is shipped to them, results come back). "
                                   "The client writes OUT/variants/<key>.csv and a row of OUT/summary.csv (status "
                                   "ok/failed/timeout, error, wall time, metrics), atomically. A sweep into an "
                                   "existing OUT merges into it; variants already done are not run again.",
                       epilog="example: ncfmu sweep lathe_roughing --vary seq.block[1].Xd=0.4,0.5,0.6 --workers 2 "
                              "--out sweep_xd")
    p.add_argument("system", help="system name or path of an .ssp file")
    p.add_argument("--vary", action="append", required=True, metavar="INSTANCE.VAR=V1,V2,...",
                   help="values of one parameter (repeat for more: the product is run)")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--workers", type=int, default=2,
                       help="worker processes of a local dask cluster (default 2; 0: serial, no dask)")
    group.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="address of a running dask scheduler, e.g. tcp://127.0.0.1:8786")
    group.add_argument("--scheduler-file", default=None, metavar="FILE",
                       help="the scheduler file of a running dask scheduler (dask scheduler --scheduler-file FILE)")
    p.add_argument("--stop-time", type=float, default=None, help="stop time in s (default: the system's)")
    p.add_argument("--out", required=True, help="folder for summary.csv and variants/")
    p.add_argument("--record", nargs="+", default=None, metavar="NAME",
                   help="outputs kept per variant, INSTANCE.VARIABLE (default: the axes' positions and what the "
                        "summary metrics read)")
    p.add_argument("--output-interval", type=float, default=None, metavar="S",
                   help="keep every S seconds of the trajectories (a whole multiple of the system's step)")
    p.add_argument("--timeout", type=float, default=None, metavar="S",
                   help="wall-clock seconds a variant may take; over it the variant is recorded as 'timeout'")
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser("plot", help="plot a result CSV (positions, errors, path with envelope) or a sweep summary.csv")
    p.add_argument("file", help="OUT/SYSTEM.csv from 'ncfmu run', or OUT/summary.csv from 'ncfmu sweep'")
    p.add_argument("--system", default=None, help="system the CSV came from (default: from the file name)")
    p.add_argument("--png", default=None, help="output file (default: the CSV's name with .png)")
    p.set_defaults(func=cmd_plot)

    p = sub.add_parser("serve", help="run a system in real time behind an OPC UA server (virtual commissioning)",
                       description="Run the system with simulated time paced to the wall clock behind an OPC UA "
                                   "server: clients read every variable (ns urn:ncfmu:SYSTEM, NodeId "
                                   "INSTANCE.VARIABLE), force inputs, set tunable parameters, and Pause/Resume/"
                                   "Stop/Reset the Simulation object. Stops on Ctrl-C, SIGTERM, Stop or the stop "
                                   "time, writes what it recorded and exits 0.", epilog=EPILOG)
    p.add_argument("system", nargs="?", default="lathe_roughing", help="system name or path of an .ssp file")
    p.add_argument("--set", action="append", metavar="INSTANCE.VAR=VALUE", help="start value or parameter")
    p.add_argument("--endpoint", default="opc.tcp://127.0.0.1:4840/ncfmu",
                   help="where the server listens (default opc.tcp://127.0.0.1:4840/ncfmu; another address than "
                        "the loopback needs --user)")
    p.add_argument("--speed", type=float, default=1.0,
                   help="simulated seconds per wall-clock second (default 1; 0: as fast as possible)")
    p.add_argument("--stop-time", type=float, default=None, help="stop at this simulated time (default: never)")
    p.add_argument("--step", type=float, default=None, help="communication step in s (default: the system's)")
    p.add_argument("--record", nargs="+", default=None, metavar="NAME",
                   help="outputs recorded, INSTANCE.VARIABLE (default: every output); needs --out")
    p.add_argument("--out", default=None, help="folder for SYSTEM.csv and session_inputs.csv (the writes, "
                                               "replayable with 'ncfmu run --input')")
    p.add_argument("--user", action="append", metavar="NAME:PASSWORD",
                   help="a user who may connect (then only users connect; required off the loopback)")
    p.add_argument("--certificate", type=Path, default=None,
                   help="server certificate: adds the Basic256Sha256 SignAndEncrypt policy (with --private-key)")
    p.add_argument("--private-key", type=Path, default=None, help="the certificate's private key")
    p.set_defaults(func=cmd_serve)

    p = sub.add_parser("validate", help="validate every FMU (fmpy) and SSP (SSP 1.0 schema) and list problems")
    p.set_defaults(func=cmd_validate)

    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except NcfmuError as err:
        print(f"ncfmu {args.command}: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
