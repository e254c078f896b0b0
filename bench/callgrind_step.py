"""Instructions a step, per FMU and per FMI call, counted by callgrind: ``python bench/callgrind_step.py``.

``[--systems lathe_taper lathe_roughing] [--stop-time 2] [--python PY] [--cwd DIR]``

A wall clock on a shared machine says little; an instruction count does not depend on the load. This runs
``OpenSystem(archive).run(stop_time)`` (the C loop, what ``compare.py`` times) under ``valgrind --tool=callgrind``
and reads the profile: every call the C loop (``ncfmu_loop``) makes
into an FMU's binary (``fmi2SetReal``, ``fmi2DoStep``, ``fmi2GetBoolean``, ...) with its inclusive cost, summed
per FMU (the binary's file name) and per call, divided by the steps run (imports, instantiation and
initialisation are outside the loop, so not counted).

``--keep DIR`` keeps each profile (``callgrind_annotate --inclusive=yes DIR/callgrind.<system>.out``: which
controller function costs what). ``--python`` and ``--cwd`` count another checkout's build (its venv's python,
its worktree), e.g. the ones ``compare.py`` keeps under ``~/.cache/ncfmu-compare/``.
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

# Runs in the checkout under test.
RUNNER = r"""
import sys
from pathlib import Path
from ncfmu.project import OpenSystem
archive, stop = Path(sys.argv[1]), float(sys.argv[2])
with OpenSystem(archive) as opened:
    result = opened.run(stop_time=stop)
    print("rows", len(result.data), "loop", getattr(opened.master, "loop_used", "?"))
"""


def parse(path: Path) -> dict[tuple[str, str], int]:
    """(binary, called function) -> inclusive instructions of the FMI calls the C loop made.

    The loop's own function is entered by a jump from libffi (ctypes), so callgrind books its body to
    libffi's function: the calls counted are those made from the loop's ``send`` and ``read_outputs`` and the
    ``fmi2DoStep`` calls made from there (the Python side makes none: every step runs in the loop)."""
    names: dict[str, dict[str, str]] = {"ob": {}, "fn": {}}
    calls: dict[tuple[str, str], int] = collections.Counter()
    fn = ob = cob = cfn = ""
    pending_call = False
    name_re = re.compile(r"^(c?)(ob|fn)=(?:\((\d+)\))?\s*(.*)$")
    with open(path) as f:
        for line in f:
            m = name_re.match(line)
            if m:
                called, kind, ident, text = m.groups()
                if ident and text:
                    names[kind][ident] = text
                value = names[kind].get(ident, text) if ident else text
                if kind == "ob":
                    if called:
                        cob = value
                    else:
                        ob = cob = value
                elif called:
                    cfn = value
                else:
                    fn, cob = value, ob
                continue
            if line.startswith("calls="):
                pending_call = True
                continue
            if pending_call:
                pending_call = False
                from_loop = (fn in ("send", "read_outputs") and "ncfmu_loop" in ob) or (
                    "libffi" in ob and cfn == "fmi2DoStep")
                if from_loop and cfn.startswith("fmi2"):
                    parts = line.split()
                    calls[(Path(cob).name.removesuffix(".so"), cfn)] += int(parts[1])
    return calls


def count(system: str, stop: float, python: str, cwd: Path, keep: Path | None = None) -> dict:
    archive = cwd / "ssp" / f"{system}.ssp"
    with tempfile.TemporaryDirectory() as tmp:
        out = (keep / f"callgrind.{system}.out") if keep else Path(tmp) / "callgrind.out"
        cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", "--compress-strings=no",
               "--compress-pos=no",
               python, "-c", RUNNER, str(archive), repr(stop)]
        run = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True,
                             env={**os.environ, "PYTHONHASHSEED": "0"})
        if run.returncode:
            raise SystemExit(f"{system}: valgrind failed:\n{run.stderr[-3000:]}")
        calls = parse(out)
    steps = round(stop / 1e-3)
    return {"system": system, "steps": steps, "total": sum(calls.values()) / steps,
            "calls": {k: v / steps for k, v in calls.items()}}


def report(r: dict) -> None:
    print(f"{r['system']}: {r['total'] / 1e3:.1f}k instructions a step in the C loop's FMI calls ({r['steps']} steps)")
    by_fmu: dict[str, float] = collections.Counter()
    for (binary, _), v in r["calls"].items():
        by_fmu[binary] += v
    for binary, v in sorted(by_fmu.items(), key=lambda kv: -kv[1]):
        parts = ", ".join(f"{fn.removeprefix('fmi2')} {c / 1e3:.1f}k" for (b, fn), c in
                          sorted(r["calls"].items(), key=lambda kv: -kv[1]) if b == binary and c >= 50)
        print(f"  {binary:<22} {v / 1e3:7.1f}k   {parts}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--systems", nargs="+", default=["lathe_taper", "lathe_roughing"])
    ap.add_argument("--stop-time", type=float, default=2.0)
    ap.add_argument("--python", default=sys.executable)
    ap.add_argument("--cwd", type=Path, default=REPO)
    ap.add_argument("--keep", type=Path, default=None,
                    help="keep the profiles as DIR/callgrind.<system>.out (for callgrind_annotate: a function's share)")
    args = ap.parse_args(argv)
    for system in args.systems:
        report(count(system, args.stop_time, args.python, args.cwd, args.keep))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
