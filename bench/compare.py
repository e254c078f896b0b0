"""Two commits side by side: ``python bench/compare.py REV_A REV_B [--systems ...] [--repeats N]``.

Run this before claiming that a change made a step faster or slower. Each revision gets a git worktree and a
venv of its own (cached under ``--work``, default ``~/.cache/ncfmu-compare/<commit>``: installed with the
pins of *this* checkout's ``.ci/constraints.txt``, so both sides run the same dependencies, then
``ncfmu build``). The runs are interleaved (A, B, A, B, ...), each in a fresh process, and the best of N is
kept per revision and system -- the least disturbed run, since a loaded machine only ever adds time. What is
timed is what ``bench/run.py`` times: ``OpenSystem(archive).run(stop_time=...)`` with the C loop (the wall
time the master reports), not the import, extraction or instantiation.

Printed per system: microseconds per 1 ms of simulated time on each side (= us per step at the systems'
1 ms step), the ratio B / A (below 1: B is faster), and whether both sides recorded the same trajectory
(a digest of every recorded column): a speed change should not change the run. The machine's load average is
printed first: the ratio is fair on a loaded machine (both sides share the load, interleaved), the absolute
numbers are not.

``--sweep`` times ``ncfmu sweep`` instead, end to end (launch to exit, as a user runs it), on the 16 lathe_taper
variants of ``bench/sweep_cpu.py`` (whole cycles, ``--stop-time`` default 50 s here): serially (``--workers 0``),
on 2 workers, and as two plain processes at once (two ``--workers 0`` halves, no dask: what the machine gives two
busy processes). Printed per kind: best wall of each side, B / A, and whether every variant's file is the same
bytes on both sides; per side, the pair's wall over the 2-worker sweep's (1: the sweep loses nothing to dask).

``--compiled a|b|both`` installs that side with the ``compiled`` extra (mypyc; the FMUs then carry the
controllers compiled). ``compare.py HEAD HEAD --compiled b`` runs one revision's pure build against its compiled
one: the compiled controllers' gain alone, and whether both record the same trajectory.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
DEFAULT_SYSTEMS = ("lathe_taper", "lathe_roughing")

# Runs inside a revision's venv, in its worktree: the timed run and a digest of what it recorded.
RUNNER = r"""
import hashlib, json, sys
from pathlib import Path
from ncfmu.project import OpenSystem
archive, stop_time = Path(sys.argv[1]), float(sys.argv[2])
with OpenSystem(archive) as opened:
    result = opened.run(stop_time=stop_time)
    loop = getattr(opened.master, "loop_used", "?")
digest = hashlib.sha256()
for name in sorted(result.data.dtype.names):
    digest.update(name.encode()); digest.update(result.data[name].tobytes())
print(json.dumps({"wall": result.wall_time, "rows": len(result.data), "loop": loop,
                  "digest": digest.hexdigest()}))
"""


class CompareError(Exception):
    """A revision that cannot be checked out, installed or built."""


def resolve(rev: str) -> str:
    out = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--verify", f"{rev}^{{commit}}"],
                         capture_output=True, text=True)
    if out.returncode:
        raise CompareError(f"not a commit: {rev!r} ({out.stderr.strip()})")
    return out.stdout.strip()


def prepare(sha: str, work: Path, constraints: Path, compiled: bool = False) -> tuple[Path, Path]:
    """The revision's worktree and venv python, built once and cached (a 'ready' marker after the build);
    ``compiled``: installed with the ``compiled`` extra (mypyc), so ``ncfmu build`` compiles the controllers
    where the revision can (a revision without the extra builds as it always did); else built with ``--pure`` where
    the revision has it (mypy now comes in without the extra: a plain ``ncfmu build`` compiled the "pure" side too).
    A cache entry prepared before that rule is built again (its marker says ``pure`` after)."""
    home = work / (sha[:12] + ("-compiled" if compiled else ""))
    src, venv = home / "src", home / "venv"
    python = venv / "bin" / "python"
    marker = home / "ready"
    build = [str(venv / "bin" / "ncfmu"), "build", *([] if compiled else ["--pure"])]
    if marker.is_file() and (compiled or marker.read_text().split()[1:] == ["pure"]):
        return src, python
    if marker.is_file():    # prepared before the rule above: only built again
        steps = [build]
    else:
        if home.exists():       # an interrupted preparation: start it again
            subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(src)], capture_output=True)
            shutil.rmtree(home, ignore_errors=True)
        home.mkdir(parents=True)
        steps = [
            ["git", "-C", str(REPO), "worktree", "add", "--detach", str(src), sha],
            [sys.executable, "-m", "venv", str(venv)],
            [str(python), "-m", "pip", "install", "-q", "-c", str(constraints), "-e",
             f"{src}[compiled]" if compiled else str(src)],
            build,
        ]
    for cmd in steps:
        if cmd[-1] == "--pure" and "--pure" not in subprocess.run(
                [str(venv / "bin" / "ncfmu"), "build", "--help"], capture_output=True, text=True).stdout:
            cmd = cmd[:-1]      # a revision from before the compiled build: its build is pure
        print(f"[{sha[:10]}] {' '.join(cmd[:4])} ...", file=sys.stderr, flush=True)
        out = subprocess.run(cmd, cwd=src if src.exists() else REPO, capture_output=True, text=True)
        if out.returncode:
            raise CompareError(f"{sha[:10]}: {' '.join(cmd)} failed:\n{out.stdout[-2000:]}{out.stderr[-2000:]}")
    marker.write_text(sha + ("\n" if compiled else " pure\n"))
    return src, python


def run_once(src: Path, python: Path, system: str, stop_time: float) -> dict:
    archive = src / "ssp" / f"{system}.ssp"
    out = subprocess.run([str(python), "-c", RUNNER, str(archive), repr(stop_time)], cwd=src,
                         capture_output=True, text=True)
    if out.returncode:
        raise CompareError(f"{src}: {system} failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


SWEEP_XD = "seq.block[1].Xd=0.3,0.35,0.4,0.45,0.5,0.55,0.6,0.65"
SWEEP_KINDS = ("serial", "2 workers", "pair")


def sweep_once(src: Path, python: Path, kind: str, stop_time: float, out: Path) -> dict:
    """One timed ``ncfmu sweep`` of ``kind`` in a revision's venv, launch to exit: its wall and a digest of the
    variants' files (name and bytes)."""
    ncfmu = str(python.parent / "ncfmu")
    archive = str(src / "ssp" / "lathe_taper.ssp")

    def command(feeds: str, workers: int, folder: Path) -> list[str]:
        return [ncfmu, "sweep", archive, "--vary", SWEEP_XD, "--vary", f"seq.block[1].feed={feeds}",
                "--workers", str(workers), "--stop-time", repr(stop_time), "--out", str(folder)]
    shutil.rmtree(out, ignore_errors=True)
    if kind == "pair":
        commands = [command("3", 0, out / "a"), command("4", 0, out / "b")]
    else:
        commands = [command("3,4", 2 if kind == "2 workers" else 0, out / "a")]
    # bytecode written as a user's machine writes it (a shell may have turned it off): both sides alike
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    start = time.perf_counter()
    procs = [subprocess.Popen(cmd, cwd=src, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for cmd in commands]
    answers = [p.communicate() for p in procs]
    wall = time.perf_counter() - start
    for p, (stdout, stderr) in zip(procs, answers):
        if p.returncode not in (0, 3, 4):          # a variant's verdict is not the bench's business
            raise CompareError(f"{src}: {' '.join(p.args)} exited {p.returncode}:\n{stdout[-1000:]}{stderr[-1000:]}")
    digest = hashlib.sha256()
    files = sorted(f for folder in out.iterdir() for f in (folder / "variants").iterdir())
    for f in sorted(files, key=lambda f: f.name):
        digest.update(f.name.encode())
        digest.update(f.read_bytes())
    return {"wall": wall, "files": len(files), "digest": digest.hexdigest()}


def compare_sweeps(sides: dict, stop_time: float, repeats: int, work: Path) -> dict:
    """``--sweep``: every kind of SWEEP_KINDS on both sides, interleaved (A, B for each kind in each round)."""
    rev_a, rev_b = sides
    walls: dict = {kind: {rev_a: [], rev_b: []} for kind in SWEEP_KINDS}
    digests: dict = {kind: {} for kind in SWEEP_KINDS}
    for _ in range(repeats):
        for kind in SWEEP_KINDS:
            for rev in (rev_a, rev_b):
                _, src, python = sides[rev]
                once = sweep_once(src, python, kind, stop_time, work / "sweep-out")
                walls[kind][rev].append(once["wall"])
                digests[kind][rev] = (once["files"], once["digest"])
    results: dict = {"kinds": {}}
    print(f"{'sweep':<12}{'A s':>8}{'B s':>8}{'B/A':>8}  same files")
    for kind in SWEEP_KINDS:
        best = {rev: min(w) for rev, w in walls[kind].items()}
        same = digests[kind][rev_a] == digests[kind][rev_b]
        print(f"{kind:<12}{best[rev_a]:>8.2f}{best[rev_b]:>8.2f}{best[rev_b] / best[rev_a]:>8.3f}  "
              f"{'yes' if same else 'NO'} ({digests[kind][rev_b][0]} files)")
        results["kinds"][kind] = {"a_best_s": best[rev_a], "b_best_s": best[rev_b], "same_files": same,
                                  "a_walls": walls[kind][rev_a], "b_walls": walls[kind][rev_b]}
    one = {digests[kind][rev_b] for kind in SWEEP_KINDS}
    print("every kind wrote the same files: " + ("yes" if len(one) == 1 else "NO"))
    for side in ("a", "b"):
        ratio = results["kinds"]["pair"][f"{side}_best_s"] / results["kinds"]["2 workers"][f"{side}_best_s"]
        results[f"{side}_pair_over_2_workers"] = ratio
        print(f"{side.upper()}: two plain processes' wall / the 2-worker sweep's: {ratio:.3f}")
    results["same_files_every_kind"] = len(one) == 1
    return results


def side_labels(rev_a: str, rev_b: str, compiled: str | None) -> tuple[str, str]:
    """The sides' names, distinct: their revisions; for one revision, also how each side is built (its pure
    and compiled builds), and an A/A run of one build (the noise) as A and B."""
    if rev_a != rev_b:
        return rev_a, rev_b
    build_a, build_b = ("compiled" if compiled in (side, "both") else "pure" for side in ("a", "b"))
    if build_a != build_b:
        return f"{rev_a} ({build_a})", f"{rev_b} ({build_b})"
    return f"{rev_a} (A, {build_a})", f"{rev_b} (B, {build_b})"


def compare(rev_a: str, rev_b: str, systems: list[str], stop_time: float, repeats: int, work: Path,
            compiled: str | None = None, sweep: bool = False) -> dict:
    constraints = REPO / ".ci" / "constraints.txt"
    labels = side_labels(rev_a, rev_b, compiled)
    sides = {}
    for label, rev, side in zip(labels, (rev_a, rev_b), ("a", "b")):
        sha = resolve(rev)
        sides[label] = (sha, *prepare(sha, work, constraints, compiled in (side, "both")))
    rev_a, rev_b = labels                  # from here on, a side is named by its label
    load = os.getloadavg()[0]
    print(f"load average {load:.2f} on {os.cpu_count()} cores"
          + (" -- loaded: trust the ratios, not the absolute numbers" if load > 0.5 else ""))
    results: dict = {"load_average": load, "stop_time": stop_time, "repeats": repeats, "compiled": compiled,
                     "a": {"rev": rev_a, "sha": sides[rev_a][0]}, "b": {"rev": rev_b, "sha": sides[rev_b][0]},
                     "systems": {}}
    print(f"A = {rev_a} ({sides[rev_a][0][:10]}), B = {rev_b} ({sides[rev_b][0][:10]}); "
          f"{stop_time:g} s simulated, best of {repeats}, interleaved")
    if sweep:
        results.update(compare_sweeps(sides, stop_time, repeats, work))
        results["load_average_after"] = os.getloadavg()[0]
        return results
    print(f"{'system':<18}{'A us/ms':>10}{'B us/ms':>10}{'B/A':>8}  same run  loops")
    for system in systems:
        walls: dict[str, list[float]] = {rev_a: [], rev_b: []}
        last: dict[str, dict] = {}
        for _ in range(repeats):
            for rev in (rev_a, rev_b):
                _, src, python = sides[rev]
                last[rev] = run_once(src, python, system, stop_time)
                walls[rev].append(last[rev]["wall"])
        best = {rev: min(w) * 1e6 / (stop_time * 1e3) for rev, w in walls.items()}
        ratio = best[rev_b] / best[rev_a]
        same = last[rev_a]["digest"] == last[rev_b]["digest"]
        print(f"{system:<18}{best[rev_a]:>10.2f}{best[rev_b]:>10.2f}{ratio:>8.3f}  {'yes' if same else 'NO ':<8}  "
              f"{last[rev_a]['loop']}/{last[rev_b]['loop']}")
        results["systems"][system] = {"a_us_per_ms": best[rev_a], "b_us_per_ms": best[rev_b], "ratio_b_over_a": ratio,
                                      "same_trajectory": same, "a_walls": walls[rev_a], "b_walls": walls[rev_b],
                                      "a_median": statistics.median(walls[rev_a]),
                                      "b_median": statistics.median(walls[rev_b])}
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rev_a", help="the baseline commit (e.g. HEAD~1)")
    parser.add_argument("rev_b", help="the commit measured against it (e.g. HEAD)")
    parser.add_argument("--systems", nargs="+", default=list(DEFAULT_SYSTEMS))
    parser.add_argument("--stop-time", type=float, default=None,
                        help="simulated seconds a run (default 10; with --sweep, a variant's limit: 50)")
    parser.add_argument("--repeats", type=int, default=3, help="runs a side and system, best kept (default 3)")
    parser.add_argument("--work", type=Path, default=Path.home() / ".cache" / "ncfmu-compare",
                        help="where the revisions' worktrees and venvs are kept")
    parser.add_argument("--json", type=Path, help="also write the results here")
    parser.add_argument("--compiled", choices=("a", "b", "both"),
                        help="install that side (or both) with the 'compiled' extra (mypyc): the FMUs a user with it "
                             "builds; 'b' with REV_A == REV_B measures the compiled controllers alone")
    parser.add_argument("--sweep", action="store_true",
                        help="time `ncfmu sweep` end to end: serial, 2 workers and two plain processes")
    args = parser.parse_args(argv)
    if args.stop_time is None:
        args.stop_time = 50.0 if args.sweep else 10.0
    if args.repeats < 1 or not args.stop_time > 0:
        parser.error("--repeats must be >= 1 and --stop-time > 0")
    try:
        results = compare(args.rev_a, args.rev_b, args.systems, args.stop_time, args.repeats, args.work,
                          args.compiled, args.sweep)
    except CompareError as exc:
        print(f"bench/compare.py: {exc}", file=sys.stderr)
        return 2
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
