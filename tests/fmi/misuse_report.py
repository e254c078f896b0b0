"""What the two adversarial hosts share (misuse_host.py: the FMI 2.0 layer, misuse3_host.py: the FMI 3.0 layer):
the report, one line per case flushed at once (a crash names the case it died in), and the cases whose shape is
the same in both FMI versions -- every call with handles that are not a live instance, the frees that must do
nothing, and the time line of doStep."""

from __future__ import annotations

import re
import subprocess
import tempfile
import zipfile
from collections.abc import Callable, Iterable
from pathlib import Path

results: list[bool] = []


def case(name: str, held: bool, what: str) -> None:
    results.append(held)
    print("CASE", name, "HELD" if held else "BROKEN", what, flush=True)


def announce(name: str) -> None:
    print("TRY", name, flush=True)


def summary() -> None:
    print("CASES", len(results), "HELD", sum(results), flush=True)


def bad_instantiations(cases: dict[str, dict], make: Callable[..., object], silent: dict,
                       log: list, error: int) -> None:
    """Each instantiation ``make(**kwargs)`` returns NULL with one error line to the host's logger; made
    again with ``silent`` (no logger), NULL too."""
    for name, kwargs in cases.items():
        announce(f"instantiate_{name}")
        log.clear()
        c = make(**kwargs)
        case(f"instantiate_{name}", not c and len(log) == 1 and log[0][0] == error, f"{c!r} {log}")
        announce(f"instantiate_{name}_no_logger")
        c = make(**silent, **kwargs)
        case(f"instantiate_{name}_no_logger", not c, repr(c))


def refused_everywhere(calls: dict[str, Callable[[object], int]], handles: Iterable[tuple[str, object]],
                       what: str, error: int) -> None:
    """Every call with every handle that is not a live instance of this binary returns ``error``."""
    for label, handle in handles:
        for fn, call in calls.items():
            announce(f"{label}_{fn}")
            result = call(handle)
            case(f"{label}_{what}_{fn}", result == error, f"returned {result}")


def frees_do_nothing(free: Callable[[object], None], freed: object) -> None:
    """Freeing NULL, and freeing a freed instance again, return and change nothing."""
    announce("free_null")
    free(None)
    case("free_null_instance", True, "returned")
    announce("double_free")
    free(freed)
    case("double_free_instance", True, "returned")


def time_line(step: Callable[..., int], said: Callable[[str], bool], clear: Callable[[], None], ok: int,
              error: int, more: dict[str, tuple[Callable[[], int], int, str | None]] | None = None) -> None:
    """After steps from 0 and 1 ms: a step back in time, one skipping ahead and one of 1e-12 s are refused
    (saying why), the one continuing at 2 ms is taken; ``more`` cases between them (each a call, the status
    expected and what the log says)."""
    first = [step(0.0), step(1e-3)]
    checks = {
        "step_back_in_time": (lambda: step(0.0), error, "expected"),
        "step_skipping_ahead": (lambda: step(5e-3), error, "expected"),
        "step_of_1e-12_s": (lambda: step(2e-3, 1e-12), error, "below 1 ns"),
        **(more or {}),
        "step_continuing": (lambda: step(2e-3), ok, None),
    }
    for name, (call, expected, says) in checks.items():
        announce(name)
        clear()
        result = call()
        case(name, first == [ok, ok] and result == expected and (says is None or said(says)), f"returned {result}")


# -- for the tests that run a host ------------------------------------------------------------------------
def exported_functions(fmu: Path, platform: str, prefix: str) -> set[str]:
    """The functions named ``prefix``* that the FMU's binary exports (nm -D)."""
    with zipfile.ZipFile(fmu) as z, tempfile.TemporaryDirectory() as tmp:
        binary = z.extract(f"binaries/{platform}/{fmu.stem}.so", tmp)
        out = subprocess.run(["nm", "-D", "--defined-only", binary], capture_output=True, text=True, check=True)
    return {line.split()[-1] for line in out.stdout.splitlines() if line.split()[-1].startswith(prefix)}


def run_host(host: Path, *args: str) -> tuple[int, int, set[str]]:
    """Runs ``host`` on ``args`` in a process of its own: it did not die and no case broke; the number of cases,
    of those that held, and the functions its bad-handle cases covered."""
    import sys
    proc = subprocess.run([sys.executable, str(host), *args], capture_output=True, text=True, timeout=300)
    tried = re.findall(r"^TRY (\S+)", proc.stdout, re.MULTILINE)
    assert proc.returncode == 0, f"died in case {tried[-1] if tried else '?'}: {proc.stderr[-2000:]}"
    broken = [line for line in proc.stdout.splitlines() if line.startswith("CASE") and " BROKEN " in line]
    assert broken == []
    counts = re.search(r"^CASES (\d+) HELD (\d+)$", proc.stdout, re.MULTILINE)
    calls = re.search(r"^CALLS (.*)$", proc.stdout, re.MULTILINE)
    assert counts and calls, proc.stdout[-500:]
    return int(counts.group(1)), int(counts.group(2)), set(calls.group(1).split())
