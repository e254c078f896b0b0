"""The FMUs in a native C host (tests/native/fmi_host.c) with an empty environment: no Python in the host.

- the controller FMUs find and load a Python runtime themselves and run; with none to be found they fail
  at fmi2Instantiate with one message, said once;
- a native host exits cleanly, every time (pythonfmu's double release of its interpreter state at exit);
- the controller FMUs carry only code that needs the Python standard library;
- the native ServoAxis and SpindleDrive need no Python at all.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from fmpy import extract, read_model_description

from ncfmu.catalogue import native_models

HOST_C = Path(__file__).resolve().parents[1] / "native" / "fmi_host.c"


@pytest.fixture(scope="session")
def fmi_host(tmp_path_factory) -> Path:
    from ncfmu.fmi.builder import fmi_headers
    exe = tmp_path_factory.mktemp("host") / "fmi_host"
    subprocess.run(["cc", "-O1", "-Wall", f"-I{fmi_headers()}", "-o", str(exe), str(HOST_C), "-ldl", "-lpthread"],
                   check=True)
    return exe


def unpack(fmu: Path, where: Path) -> tuple[str, str, dict[str, int]]:
    """(binary, guid, value references) of ``fmu`` unpacked into ``where``."""
    md = read_model_description(str(fmu))
    folder = extract(str(fmu), unzipdir=str(where))
    return (f"{folder}/binaries/linux64/{md.coSimulation.modelIdentifier}.so", md.guid,
            {v.name: v.valueReference for v in md.modelVariables})


def run_host(host: Path, binary: str, guid: str, instances: int, steps: int, out_vr: int, *inputs: str,
             env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    resources = "file://" + str(Path(binary).parents[2] / "resources")
    command = ["env", "-i", *(f"{k}={v}" for k, v in (env or {}).items()), str(host), binary, guid, resources,
               str(instances), str(steps), str(out_vr), *inputs]
    return subprocess.run(command, capture_output=True, text=True, timeout=120)


def outputs(proc: subprocess.CompletedProcess) -> list[float]:
    return [float(v) for v in re.findall(r"^OUT \d+ (\S+)$", proc.stdout, re.M)]


@pytest.mark.slow
def test_controller_fmu_loads_python_itself_and_exits_cleanly(fmus, fmi_host, tmp_path):
    """CutSequencer in a host with no Python and an empty environment, 12 runs of 1-3 instances: each runs
    the approach (X towards its clearance first) and exits 0 (before: rc 134 in about 1 run of 3)."""
    binary, guid, vr = unpack(fmus["CutSequencer"], tmp_path / "fmu")
    for run in range(12):
        n = run % 3 + 1
        proc = run_host(fmi_host, binary, guid, n, 300, vr["x_cmd"], f"{vr['x_pos']}=30.0", f"{vr['z_pos']}=2.0")
        assert proc.returncode == 0, (run, proc.returncode, proc.stdout[-800:], proc.stderr[-800:])
        got = outputs(proc)
        assert len(got) == n and all(v == got[0] for v in got)
        assert "cannot load" not in proc.stderr and "undefined symbol" not in proc.stderr


def test_instances_made_on_threads_at_once_each_get_their_own(fmus, fmi_host, tmp_path):
    """Eight instances instantiated on eight threads at the same moment, in a host without Python: the runtime
    is loaded once (before the lock: a crash in 20 of 20 runs) and every instance runs its own controller."""
    binary, guid, vr = unpack(fmus["CutSequencer"], tmp_path / "fmu")
    for run in range(3):
        proc = run_host(fmi_host, binary, guid, -8, 100, vr["x_cmd"], f"{vr['x_pos']}=30.0", f"{vr['z_pos']}=2.0")
        assert proc.returncode == 0, (run, proc.returncode, proc.stdout[-800:], proc.stderr[-800:])
        got = outputs(proc)
        assert len(got) == 8 and all(v == got[0] for v in got)


def test_the_recorded_python_is_used_whatever_python_is_on_path(fmus, fmi_host, tmp_path):
    """A host with an ordinary PATH: the embedded interpreter must not take /usr/bin/python3's library."""
    binary, guid, vr = unpack(fmus["AreaLimiter"], tmp_path / "fmu")
    proc = run_host(fmi_host, binary, guid, 1, 50, vr["ref_cmd"],
                    env={"PATH": "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"})
    assert proc.returncode == 0, proc.stdout[-1500:] + proc.stderr[-800:]
    assert "ModuleNotFoundError" not in proc.stdout


def test_no_python_runtime_is_one_clear_message(fmus, fmi_host, tmp_path):
    binary, guid, vr = unpack(fmus["OperatorPanel"], tmp_path / "fmu")
    proc = run_host(fmi_host, binary, guid, 1, 10, 0, env={"NCFMU_LIBPYTHON": "/nonexistent/libpython3.so"})
    assert proc.returncode == 2                                       # fmi2Instantiate returned NULL
    said = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(said) == 1 and "needs a Python runtime" in said[0] and "/nonexistent/libpython3.so" in said[0]
    logged = [ln for ln in proc.stdout.splitlines() if ln.startswith("LOG")]
    assert len(logged) == 1 and logged[0].startswith("LOG 3 ") and "NCFMU_LIBPYTHON" in logged[0]


def test_the_override_variable_chooses_the_runtime(fmus, fmi_host, tmp_path):
    import sysconfig
    lib = Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("INSTSONAME")
    binary, guid, vr = unpack(fmus["OperatorPanel"], tmp_path / "fmu")
    (Path(binary).parents[2] / "resources" / "ncfmu_python.txt").write_text("/nonexistent/recorded.so\n")
    proc = run_host(fmi_host, binary, guid, 1, 10, 0, env={"NCFMU_LIBPYTHON": str(lib)})
    assert proc.returncode == 0, proc.stderr[-800:]


#: Imports of the vendored package that are optional, guarded by ImportError: (module, file in the package).
GUARDED = {("numpy", "fmi/state.py"), ("mypy_extensions", "controllers/mypyc_compat.py")}


def test_controller_fmus_carry_only_standard_library_code(fmus):
    """Every Python file a controller FMU carries imports only the standard library, pythonfmu's slave API
    (carried too) or its own vendored package: no numpy, scipy, control, fmpy."""
    allowed = set(sys.stdlib_module_names) | {"pythonfmu", "__future__"}
    for name, fmu in fmus.items():
        if name in native_models():
            continue
        with zipfile.ZipFile(fmu) as z:
            files = [n for n in z.namelist() if n.startswith("resources/") and n.endswith(".py")]
            vendored = {n.split("/")[1] for n in files if n.split("/")[1].startswith("ncfmu_")}
            own = vendored | {Path(n).stem for n in files if n.count("/") == 1}
            assert vendored and not any("/cli.py" in n or "/cosim/" in n or "/servo/" in n for n in files), name
            for n in files:
                for node in ast.walk(ast.parse(z.read(n))):
                    if isinstance(node, ast.Import):
                        roots = [a.name.split(".")[0] for a in node.names]
                    elif isinstance(node, ast.ImportFrom) and node.level == 0:
                        roots = [node.module.split(".")[0]]
                    else:
                        continue
                    for root in roots:
                        if (root, n.split("/", 2)[-1]) in GUARDED:
                            continue                                 # optional, guarded by ImportError
                        assert root in allowed or root in own, f"{name}: {n} imports {root}"


def test_servo_runs_without_python(fmus, fmi_host, tmp_path):
    binary, guid, vr = unpack(fmus["ServoAxis"], tmp_path / "fmu")
    proc = run_host(fmi_host, binary, guid, 2, 1000, vr["pos"], f"{vr['pos_cmd']}+=0.01", f"{vr['vel_ff']}=10.0")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    # the command ramps at 10 mm/s to 10 mm; with full feed-forward the axis follows within microns
    assert outputs(proc) == [pytest.approx(10.0, abs=0.01)] * 2
    assert "python" not in subprocess.run(["ldd", binary], capture_output=True, text=True).stdout.lower()


def test_spindle_runs_without_python(fmus, fmi_host, tmp_path):
    binary, guid, vr = unpack(fmus["SpindleDrive"], tmp_path / "fmu")
    proc = run_host(fmi_host, binary, guid, 2, 1000, vr["speed"], f"{vr['speed_cmd']}=1000.0")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    # 0 -> 1000 rev/min at the torque limit takes 0.21 s; after 1 s it turns at 1000 (to an encoder count a step)
    assert outputs(proc) == [pytest.approx(1000.0, abs=0.06)] * 2
    assert "python" not in subprocess.run(["ldd", binary], capture_output=True, text=True).stdout.lower()
