"""Pacing of ``ncfmu serve``: lag and overruns at real time, and the fastest speed held without an overrun.

    python bench/serve_lag.py [--seconds 60] [--system lathe_roughing] [--json FILE]

0. A baseline: a bare loop sleeping 1 ms (no ncfmu) for up to 30 s: how late the machine wakes a thread up.
1. ``ncfmu serve SYSTEM --speed 1 --stop-time SECONDS`` as a process, with an asyncua client subscribed to both
   axes' positions at a 10 ms publishing interval (what an HMI does): prints the lag (wall clock minus the
   paced simulated time, after each chunk of steps) p50 / p99 / max and the overruns (times it fell more than
   10 ms behind). Goal on 2 cores: p99 < 5 ms, 0 overruns.
2. ``--speed 0`` (as fast as it can, still serving, the same client): simulated / wall time.
3. The headroom: the same for 10 s of wall time at doubling speeds (2, 4, 8, ...) until a speed overruns, then
   halfway between the last good and the first bad speed, twice: the fastest speed held with 0 overruns.

The numbers depend on what else the machine runs: say so with them.

    python bench/serve_lag.py --against REV [--options "--watchdog 5 --cnc"] [--repeats 3] [--seconds 30]

compares instead, side by side in one run: ``ncfmu serve`` of the commit REV (its worktree and venv from
bench/compare.py, built once and cached) with no options against this checkout's with ``--options``,
interleaved (old, new, old, new, ...), each at --speed 1 with the subscribed client, the load average beside
every trial. Claim nothing from the first mode's numbers about a change; claim from this one.

    python bench/serve_lag.py --on-off --options "--watchdog 5 --cnc" [--repeats 5] [--seconds 30]

the same, but this checkout against itself: without the options ("off") and with them ("on"), interleaved.

    python bench/serve_lag.py --on-off --browsers 2 [--repeats 3] [--seconds 30]

the same with the live page: "on" adds ``--web`` and N headless chromium browsers watching the page for the whole
run (tests/web/web_browser.py's, Debian's chromium; they share the machine's cores with the server, as they would
on an engineer's desk), "off" is the same serve (both with --options) without the page and without browsers.

Since issue 47 ``ncfmu serve`` serves the OPC 40502 model by default (``--cnc`` is its explicit form): a run
"without options" has it; ``--options "--no-cnc"`` is the side without it.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from contextlib import ExitStack
from pathlib import Path

WALL = re.compile(r"after (?P<wall>[\d.]+) s of wall time")
SUMMARY = re.compile(r"lag p50 (?P<p50>[\d.]+) ms, p99 (?P<p99>[\d.]+) ms, max (?P<max>[\d.]+) ms; "
                     r"overruns (?P<overruns>\d+)")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def watch(endpoint: str, namespace: str, axes: list[str], stop: asyncio.Event) -> int:
    """Subscribe to the axes' positions until ``stop``; the number of data changes received."""
    from asyncua import Client, ua

    class Count:
        n = 0

        def datachange_notification(self, node, val, data):
            Count.n += 1
    give_up = time.monotonic() + 120.0          # a loaded machine may take long to start a server
    while True:
        try:
            client = Client(endpoint, timeout=10)
            await client.connect()
            break
        except OSError:
            if time.monotonic() > give_up:
                raise RuntimeError(f"no server at {endpoint}") from None
            await asyncio.sleep(0.1)
    try:
        idx = await client.get_namespace_index(namespace)
        sub = await client.create_subscription(10, Count())
        await sub.subscribe_data_change([client.get_node(ua.NodeId(f"{a}.pos", idx)) for a in axes])
        await stop.wait()
    except Exception:
        pass
    finally:
        try:
            await client.disconnect()
        except Exception:
            pass
    return Count.n


def wake_up_baseline(seconds: float) -> dict:
    """The machine's own lateness: a bare loop sleeping 1 ms, how late each wake-up is (no ncfmu, no GIL
    sharing). Lateness over 10 ms here is the machine's, and shows as overruns of any paced loop."""
    late = []
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        t = time.perf_counter()
        time.sleep(0.001)
        late.append(time.perf_counter() - t - 0.001)
    late.sort()
    return {"seconds": seconds, "wake_ups": len(late), "late_p50_ms": late[len(late) // 2] * 1e3,
            "late_p99_ms": late[int(len(late) * 0.99)] * 1e3, "late_max_ms": late[-1] * 1e3,
            "over_10ms": sum(x > 0.010 for x in late)}


def watch_page(url: str, browsers: int, done: threading.Event, frames: list[int]) -> None:
    """``browsers`` headless chromium browsers on the page until ``done``; the frames each page drew."""
    sys.path.insert(0, str(Path(__file__).parent.parent / "tests" / "web"))
    from web_browser import browser
    give_up = time.monotonic() + 120.0
    while not done.is_set():
        try:
            urllib.request.urlopen(url, timeout=1).close()
            break
        except OSError:
            if time.monotonic() > give_up:
                raise RuntimeError(f"no page at {url}") from None
            time.sleep(0.1)
    with ExitStack() as stack:
        drivers = [stack.enter_context(browser()) for _ in range(browsers)]
        for d in drivers:
            d.get(url)
        done.wait()
        try:
            frames.extend(int(d.execute_script("return Number(document.body.dataset.frames || 0)")) for d in drivers)
        except Exception:           # the server ended first: the pages stand
            pass


def serve_once(system: str, speed: float, sim_seconds: float, axes: list[str], python: str = sys.executable,
               cwd: str | None = None, options: tuple[str, ...] = (), browsers: int = 0) -> dict:
    port = free_port()
    endpoint = f"opc.tcp://127.0.0.1:{port}/ncfmu"
    page = f"127.0.0.1:{free_port()}"
    if browsers:
        options = (*options, "--web", page)
    proc = subprocess.Popen([python, "-m", "ncfmu.cli", "serve", system, "--endpoint", endpoint,
                             "--speed", repr(speed), "--stop-time", repr(sim_seconds), *options],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=cwd,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})

    async def client() -> int:
        stop = asyncio.Event()
        task = asyncio.create_task(watch(endpoint, f"urn:ncfmu:{system}", axes, stop))
        while proc.poll() is None:
            await asyncio.sleep(0.2)
        stop.set()
        return await task
    done, frames = threading.Event(), []
    pages = threading.Thread(target=watch_page, args=(f"http://{page}/", browsers, done, frames), daemon=True)
    if browsers:
        pages.start()
    wall = time.perf_counter()
    changes = asyncio.run(client())
    wall = time.perf_counter() - wall
    done.set()
    if browsers:
        pages.join(60)
    out = proc.stdout.read() if proc.stdout else ""
    m = SUMMARY.search(out)
    if proc.returncode != 0 or m is None:
        raise RuntimeError(f"ncfmu serve failed (rc {proc.returncode}):\n{out}")
    w = WALL.search(out)
    return {"speed": speed, "options": list(options), "load_average": os.getloadavg()[0],
            "simulated_s": sim_seconds, "wall_s": float(w["wall"]) if w else round(wall, 2),
            "data_changes": changes, "browsers": browsers, "page_frames": frames,
            "lag_p50_ms": float(m["p50"]), "lag_p99_ms": float(m["p99"]), "lag_max_ms": float(m["max"]),
            "overruns": int(m["overruns"])}


def compare(args, axes: list[str]) -> dict:
    """Old (REV, no options) and new (this checkout, ``--options``) interleaved, at --speed 1; with ``--on-off``
    this checkout without the options ("off") and with them ("on")."""
    import shlex
    sys.path.insert(0, str(Path(__file__).parent))
    options = tuple(shlex.split(args.options))
    if args.on_off:
        sha, python, src = "this checkout", Path(sys.executable), None
    else:
        # bench/compare.py: a revision's worktree and venv
        from compare import REPO, prepare, resolve
        sha = resolve(args.against)
        src, python = prepare(sha, args.work, REPO / ".ci" / "constraints.txt")
    names = ("off", "on") if args.on_off else ("old", "new")
    load_start = os.getloadavg()
    print(f"machine: {os.cpu_count()} cores, load average {load_start[0]:.2f} (1 min) at the start")
    rows: dict[str, list[dict]] = {names[0]: [], names[1]: []}
    for k in range(args.repeats):
        for which in names:
            # with browsers, both sides get --options: they differ by the page and its browsers alone
            r = (serve_once(args.system, 1.0, args.seconds, axes, str(python), src and str(src),
                            options=options if args.browsers else ())
                 if which == names[0] else serve_once(args.system, 1.0, args.seconds, axes, options=options,
                                                      browsers=args.browsers))
            rows[which].append(r)
            label = ("this checkout, no options" if args.on_off else sha[:10]) if which == names[0] else \
                f"this checkout {args.options}" + (f" --web, {args.browsers} browsers" if args.browsers else "")
            print(f"  {k + 1} {which} ({label}): "
                  f"lag p50 {r['lag_p50_ms']:.2f} ms, p99 {r['lag_p99_ms']:.2f} ms, max {r['lag_max_ms']:.2f} ms; "
                  f"overruns {r['overruns']}; {r['data_changes']} data changes; "
                  + (f"frames drawn by the pages {r['page_frames']}; " if r["browsers"] else "") + "load average "
                  f"{r['load_average']:.2f}", flush=True)
    for which, rs in rows.items():
        p99 = sorted(r["lag_p99_ms"] for r in rs)
        print(f"{which}: lag p99 median {p99[len(p99) // 2]:.2f} ms (of {', '.join(f'{x:.2f}' for x in p99)}); "
              f"overruns {sum(r['overruns'] for r in rs)} in {len(rs)} runs of {args.seconds:g} s")
    print(f"machine: load average {os.getloadavg()[0]:.2f} (1 min) at the end")
    return {"system": args.system, "against": sha, "options": list(options), "browsers": args.browsers, **rows,
            "cores": os.cpu_count(),
            "load_average_start": load_start, "load_average_end": os.getloadavg()}


def main() -> dict:
    import logging
    logging.getLogger("asyncua").setLevel(logging.CRITICAL)     # the server going away at its stop time is expected
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--system", default="lathe_roughing")
    parser.add_argument("--seconds", type=float, default=60.0, help="simulated seconds at --speed 1 (default 60)")
    parser.add_argument("--headroom-wall", type=float, default=10.0, help="wall seconds per headroom trial")
    parser.add_argument("--json", default=None)
    parser.add_argument("--against", default=None, metavar="REV",
                        help="compare with ncfmu serve of this commit, side by side (see the docstring)")
    parser.add_argument("--on-off", action="store_true",
                        help="compare this checkout without --options and with them, side by side")
    parser.add_argument("--options", default="",
                        help="ncfmu serve options of this checkout's runs (with --against or --on-off)")
    parser.add_argument("--browsers", type=int, default=0,
                        help="with --on-off: the 'on' side serves --web with this many browsers on the page")
    parser.add_argument("--repeats", type=int, default=3, help="old/new (off/on) pairs (with --against, --on-off)")
    parser.add_argument("--work", type=Path, default=Path.home() / ".cache" / "ncfmu-compare",
                        help="where bench/compare.py keeps the revisions' worktrees and venvs")
    args = parser.parse_args()
    axes = ["x_axis", "z_axis"] if args.system.startswith("lathe") else ["x_axis"]
    if args.against is not None or args.on_off:
        result = compare(args, axes)
        if args.json:
            with open(args.json, "w") as f:
                json.dump(result, f, indent=2)
        return result
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f} (1 min) at the start")
    base = wake_up_baseline(min(args.seconds, 30.0))
    print(f"baseline: a bare 1 ms sleep loop for {base['seconds']:g} s wakes up late by p50 "
          f"{base['late_p50_ms']:.2f} ms, p99 {base['late_p99_ms']:.2f} ms, max {base['late_max_ms']:.1f} ms; "
          f"{base['over_10ms']} wake-ups more than 10 ms late (the machine's share of any overruns)")
    real = serve_once(args.system, 1.0, args.seconds, axes)
    print(f"{args.system} at --speed 1 for {args.seconds:g} s (client subscribed, 10 ms): lag p50 "
          f"{real['lag_p50_ms']:.2f} ms, p99 {real['lag_p99_ms']:.2f} ms, max {real['lag_max_ms']:.2f} ms; "
          f"overruns {real['overruns']}; {real['data_changes']} data changes delivered  "
          f"[goal p99 < 5 ms: {'met' if real['lag_p99_ms'] < 5 else 'NOT met'}; 0 overruns: "
          f"{'met' if real['overruns'] == 0 else 'NOT met'}]")
    fast = serve_once(args.system, 0.0, args.seconds, axes)
    print(f"{args.system} at --speed 0 (as fast as it can, still serving): {args.seconds:g} s in "
          f"{fast['wall_s']:.2f} s of wall time: {args.seconds / fast['wall_s']:.1f}x real time")
    trials = []

    def trial(speed: float) -> bool:
        r = serve_once(args.system, speed, speed * args.headroom_wall, axes)
        trials.append(r)
        print(f"  --speed {speed:g}: overruns {r['overruns']}, lag p99 {r['lag_p99_ms']:.2f} ms, "
              f"max {r['lag_max_ms']:.2f} ms")
        return r["overruns"] == 0
    good, bad, speed = 1.0, None, 2.0
    while bad is None and speed <= 1024:
        if trial(speed):
            good, speed = speed, speed * 2
        else:
            bad = speed
    for _ in range(2):
        if bad is None:
            break
        mid = round((good + bad) / 2, 1)
        if trial(mid):
            good = mid
        else:
            bad = mid
    print(f"headroom: the fastest --speed held with 0 overruns: {good:g}"
          + (f" (--speed {bad:g} overran)" if bad is not None else ""))
    print(f"machine: load average {os.getloadavg()[0]:.2f} (1 min) at the end")
    result = {"system": args.system, "baseline": base, "realtime": real, "as_fast_as_possible": fast,
              "headroom_speed": good, "first_overrun_speed": bad,
              "trials": trials, "cores": os.cpu_count(), "load_average_end": os.getloadavg()[0]}
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2)
    return result


if __name__ == "__main__":
    main()
