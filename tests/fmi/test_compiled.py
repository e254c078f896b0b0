"""The controllers compiled with mypyc inside the FMUs, and the pure-Python path kept beside them as the reference.

The session's FMUs (conftest) are built compiled where mypyc and a C compiler are installed (the test venv has
both: mypy is pinned in .ci/constraints.txt), so every other FMU test runs the compiled controllers; these tests
say that they really are the extensions, that the sources stand in for them on another Python, and that a pure
build gives the same trajectory, bit for bit.
"""

from __future__ import annotations

import io
import json
import logging
import pickle
import shutil
import subprocess
import sys
import sysconfig
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest

from ncfmu.fmi import builder
from ncfmu.fmi.builder import COMPILED, build_all, compiled_runtime, fmu_version, vendored_package

ROOT = Path(__file__).resolve().parents[2]
EXT = sysconfig.get_config_var("EXT_SUFFIX")
CONTROLLERS = ("CutSequencer", "AreaLimiter", "OperatorPanel")

# One CutSequencer FMU stepped through a cycle start in a fresh process: its outputs a step, and the file each
# module of its vendored package was loaded from.
STEP_ONE = textwrap.dedent("""
    import json, sys
    from ncfmu.cosim.fmu import FmuSlave, UnpackedFmu
    from ncfmu.fmi.builder import vendored_package
    from ncfmu.systems import parameters
    fmu = sys.argv[1]
    unpacked = UnpackedFmu(fmu)
    slave = FmuSlave(unpacked, "seq")
    for k, v in parameters("lathe_roughing", "seq").items():
        slave.set_start(k, v)
    slave.initialize(0.0, 1e6)
    slave.set_start("start", True)
    rows = []
    for i in range(400):
        slave.set_start("x_pos", 50.0 - 0.01 * i)
        slave.do_step(i * 1e-3, 1e-3)
        rows.append([slave.get(n) for n in ("x_cmd", "z_cmd", "subcycle")])
    package = vendored_package(fmu)
    files = {m: getattr(sys.modules[m], "__file__", None) for m in sorted(sys.modules)
             if m.split(".")[0] == package or m.endswith("__mypyc")}
    print(json.dumps({"rows": rows, "files": files, "root": str(unpacked.directory)}))
    slave.terminate()
""")

# A system run in a fresh process: every recorded variable, and where the vendored controllers came from.
RUN_SYSTEM = textwrap.dedent("""
    import pickle, sys
    from ncfmu.project import OpenSystem
    archive, out = sys.argv[1], sys.argv[2]
    with OpenSystem(archive) as opened:
        result = opened.run(stop_time=float(sys.argv[3]))
        files = {m: sys.modules[m].__file__ for m in sys.modules
                 if m.startswith("ncfmu_") and m.endswith((".limiter", ".g7x", ".lathe_program"))}
        data = {name: result[name].copy() for name in result.names}
        states = {}                 # each controller FMU's serialized state at the end (fmi2SerializeFMUstate)
        for slave in opened.slaves:
            model = slave.unpacked.model_description.modelName
            if model in ("CutSequencer", "AreaLimiter", "OperatorPanel"):
                state = slave.get_state()
                states[model] = slave.serialize_state(state)
                slave.free_state(state)
    pickle.dump({"data": data, "time": result.time.copy(), "files": files, "states": states}, open(out, "wb"))
""")


def _python(script: str, *args: object) -> str:
    proc = subprocess.run([sys.executable, "-c", script, *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


def _step_one(fmu: Path) -> dict:
    return json.loads(_python(STEP_ONE, fmu).splitlines()[-1])


def test_the_fmus_carry_the_compiled_controllers_beside_their_sources(fmus):
    """Every Python FMU of the build carries the same vendored package (one compile), with each compiled module
    as an extension beside its .py and mypyc's group library at the top of its resources."""
    packages = set()
    for name in CONTROLLERS:
        package = vendored_package(fmus[name])
        packages.add(package)
        with zipfile.ZipFile(fmus[name]) as z:
            files = set(z.namelist())
        for module in COMPILED:
            assert f"resources/{package}/{module}" in files, (name, module)
            assert f"resources/{package}/{module[:-3]}{EXT}" in files, (name, module)
        for module in ("errors.py", "controllers/geometry.py"):       # not compiled: sources only
            assert f"resources/{package}/{module[:-3]}{EXT}" not in files
        assert [f for f in files if f.startswith("resources/") and f.count("/") == 1 and f.endswith("__mypyc" + EXT)]
    assert len(packages) == 1, packages


def test_the_group_library_is_named_by_the_package_it_serves(fmus):
    """mypyc's group library is a top-level module (sys.modules is shared by every FMU of a process): its name is
    mypyc's hash of the compiled modules' full names, which carry the package's digest, so two different ncfmu
    builds load two different group libraries."""
    from mypyc.build import group_name
    from mypyc.common import shared_lib_name
    package = vendored_package(fmus["CutSequencer"])
    with zipfile.ZipFile(fmus["CutSequencer"]) as z:
        group = [Path(f).name for f in z.namelist() if f.count("/") == 1 and f.endswith("__mypyc" + EXT)]

    def name_for(package: str) -> str:
        return shared_lib_name(group_name(sorted(f"{package}.{m[:-3].replace('/', '.')}" for m in COMPILED)))
    assert group == [name_for(package) + EXT]
    assert name_for("ncfmu_000000000000") != name_for(package)


def test_a_run_loads_the_controllers_from_the_fmus_extensions(fmus):
    """Through a real run (a fresh process, an fmpy host): the vendored controller modules are the extension
    modules inside the unpacked FMU, not the sources and not the in-process ncfmu."""
    got = _step_one(fmus["CutSequencer"])
    root = Path(got["root"]).resolve()
    package = vendored_package(fmus["CutSequencer"])
    for module in COMPILED:
        name = f"{package}.{module[:-3].replace('/', '.')}"
        if name in got["files"]:
            f = Path(got["files"][name]).resolve()
            assert f.name.endswith(EXT) and root in f.parents, (name, f)
    assert Path(got["files"][f"{package}.controllers.lathe_program"]).name == f"lathe_program{EXT}"
    assert Path(got["files"][f"{package}.controllers.limiter"]).name == f"limiter{EXT}"
    assert got["files"][f"{package}.errors"].endswith("errors.py")
    assert any(m.endswith("__mypyc") for m in got["files"])
    assert len({tuple(r) for r in got["rows"]}) > 100                 # it ran: the commands moved step by step


def test_another_python_falls_back_to_the_sources(fmus, tmp_path):
    """An FMU on a Python of another ABI: its extensions (here renamed to another ABI tag) are not importable
    there, so the .py beside each is imported, and the FMU gives the same outputs, step for step."""
    fmu = fmus["CutSequencer"]
    other = tmp_path / "CutSequencer.fmu"
    alien = EXT.replace(f"cpython-{sys.version_info[0]}{sys.version_info[1]}", "cpython-399")
    assert alien != EXT
    with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(other, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            name = item.filename
            zout.writestr(name[:-len(EXT)] + alien if name.endswith(EXT) else name, zin.read(item))
    compiled, fallback = _step_one(fmu), _step_one(other)
    package = vendored_package(fmu)
    assert compiled["files"][f"{package}.controllers.lathe_program"].endswith(EXT)
    assert fallback["files"][f"{package}.controllers.lathe_program"].endswith("lathe_program.py")
    assert not any(f and f.endswith(".so") for f in fallback["files"].values())
    assert fallback["rows"] == compiled["rows"]


@pytest.mark.slow
def test_pure_and_compiled_builds_of_lathe_taper_give_identical_records(project, tmp_path):
    """The reference: lathe_taper from a pure build (``ncfmu build --pure``) and from the compiled build, each in
    its own process (both carry the same package name: in one process the first loaded would serve both),
    recorded bit for bit the same."""
    from ncfmu.cosim.ssp import pack, write_system
    from ncfmu.project import models_dir
    from ncfmu.systems import get_system
    pure_fmus = build_all(models_dir(ROOT), tmp_path / "fmus", pure=True)
    for fmu in pure_fmus:
        with zipfile.ZipFile(fmu) as z:
            assert not [n for n in z.namelist() if n.startswith("resources/") and n.endswith(".so")], fmu
    pure_seq = tmp_path / "fmus" / "CutSequencer.fmu"
    assert vendored_package(pure_seq) == vendored_package(ROOT / "fmus" / "CutSequencer.fmu")
    assert fmu_version(pure_seq) != fmu_version(ROOT / "fmus" / "CutSequencer.fmu")    # rebuilt when switched
    folder = write_system(get_system("lathe_taper"), tmp_path / "ssp")
    pure_archive = pack(folder, tmp_path / "fmus", tmp_path / "lathe_taper.ssp")
    runs = {}
    for kind, archive in (("pure", pure_archive), ("compiled", ROOT / "ssp" / "lathe_taper.ssp")):
        _python(RUN_SYSTEM, archive, tmp_path / f"{kind}.pkl", 6.0)
        runs[kind] = pickle.loads((tmp_path / f"{kind}.pkl").read_bytes())
    assert all(f.endswith(".py") for f in runs["pure"]["files"].values()) and len(runs["pure"]["files"]) == 3
    assert all(f.endswith(EXT) for f in runs["compiled"]["files"].values()) and len(runs["compiled"]["files"]) == 3
    pure, compiled = runs["pure"]["data"], runs["compiled"]["data"]
    assert list(pure) == list(compiled) and np.array_equal(runs["pure"]["time"], runs["compiled"]["time"])
    assert any(np.ptp(v) > 0 for v in compiled.values())
    for name in pure:
        assert np.array_equal(pure[name], compiled[name]), name
    # the controllers' own registers too: the compiled (native) classes save the same state, byte for byte
    assert set(runs["pure"]["states"]) == {"CutSequencer", "AreaLimiter", "OperatorPanel"}
    assert runs["pure"]["states"] == runs["compiled"]["states"]


def test_every_controller_of_the_runtime_is_compiled_with_its_base():
    """The controllers are mypyc native classes, which deepcopy (the FMU states) copies through their pickle
    state: an interpreted subclass's own attributes would be lost. So every Controller subclass of the
    runtime's controllers package lives in a compiled module, as its bases do."""
    import importlib
    import pkgutil

    import ncfmu.controllers as package
    from ncfmu.controllers.base import Controller
    for info in pkgutil.iter_modules(package.__path__):
        importlib.import_module(f"ncfmu.controllers.{info.name}")
    found, todo = set(), [Controller]
    while todo:
        cls = todo.pop()
        found.add(cls)
        todo.extend(cls.__subclasses__())
    modules = {c.__module__ for c in found if c.__module__.startswith("ncfmu.controllers.")}
    assert {"ncfmu.controllers.sequencer", "ncfmu.controllers.limiter", "ncfmu.controllers.feed"} <= modules
    compiled = {"ncfmu." + m[:-3].replace("/", ".") for m in COMPILED}
    assert modules <= compiled, modules - compiled


def test_the_compile_is_cached_once_per_runtime(project, monkeypatch):
    """The session's build compiled the runtime once; asking again finds it in the cache and compiles nothing."""
    def no_compile(*args, **kwargs):
        raise AssertionError(f"compiled again: {args}")
    monkeypatch.setattr(builder.subprocess, "run", no_compile)
    monkeypatch.setattr(builder.subprocess, "Popen", no_compile)
    cached = compiled_runtime()
    assert cached is not None and (cached / "COMPLETE").is_file()
    assert cached.parent.name == builder.runtime_digest()
    assert not list(cached.parent.glob(".compiling-*"))          # no half-written copy left beside it


def test_without_mypyc_the_build_falls_back_to_pure_with_one_warning(monkeypatch, tmp_path, caplog):
    """No mypyc (or no C compiler): no compiled runtime and one clear log line, never a BuildError."""
    monkeypatch.setenv("NCFMU_CACHE", str(tmp_path))                 # nothing cached here
    monkeypatch.setattr(builder.importlib.util, "find_spec", lambda name: None)
    with caplog.at_level(logging.WARNING, logger=builder.__name__):
        assert compiled_runtime() is None
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 1 and "mypyc is not installed" in lines[0] and "pure-Python" in lines[0]
    assert not (tmp_path / "compiled" / builder.runtime_digest()).exists() or not any(
        (tmp_path / "compiled" / builder.runtime_digest()).iterdir())


def test_a_failed_compile_falls_back_to_pure_and_caches_nothing(monkeypatch, tmp_path, caplog):
    """mypyc refusing the sources: one warning with its message, no cache entry (the next build tries again)."""
    monkeypatch.setenv("NCFMU_CACHE", str(tmp_path))

    class Refuses:              # the compile's child process, as subprocess.Popen: its log, then exit status 1
        def __init__(self, cmd, **kwargs):
            self.stdout = io.StringIO("ncfmu_x/ports.py:1: error: deliberate\n")

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def wait(self):
            return 1
    monkeypatch.setattr(builder.subprocess, "Popen", Refuses)
    with caplog.at_level(logging.WARNING, logger=builder.__name__):
        assert compiled_runtime() is None
    assert len(caplog.records) == 1 and "deliberate" in caplog.records[0].getMessage()
    folder = tmp_path / "compiled" / builder.runtime_digest()
    assert [p.name for p in folder.iterdir()] == []
    shutil.rmtree(tmp_path / "compiled")
