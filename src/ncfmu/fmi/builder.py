"""Build FMUs from the model scripts in ``models/`` with pythonfmu.

An FMU must run the code it was built from, even in a process that has imported another ncfmu
(pythonfmu FMUs share the host interpreter and ``sys.modules``). So the builder

1. copies the ``ncfmu`` runtime (``FMU_RUNTIME``) into the FMU's resources under a content-addressed name,
   ``ncfmu_<runtime digest>`` (the package's imports are relative, so it runs under any name); the digest covers
   the runtime's files only, so every Python FMU of a build carries the same package, compiled once;
2. unless built pure, ships beside those sources the runtime's controller modules (``COMPILED``) compiled with
   mypyc for the building Python (ABI-tagged extensions and mypyc's group library, cached in
   ``~/.cache/ncfmu/compiled/<runtime digest>/``): Python's import prefers an extension of its own ABI and falls
   back to the ``.py`` beside it on any other Python;
3. rewrites the model script's ``ncfmu`` imports to that name and stores the script as the unique
   module ``<Model>_<digest>`` (the digest of everything the FMU is made from);
4. completes pythonfmu's modelDescription from the ports (:mod:`.modeldesc`) and records that digest in its
   ``version`` attribute, so a stale FMU is rebuilt.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.util
import logging
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from pathlib import Path

# Imported here, at import time: once an FMU has been instantiated, pythonfmu puts that FMU's
# resources/ (which holds a pythonfmu copy *without* binaries) first on sys.path, and a builder
# imported from there would build FMUs without binaries.
from pythonfmu.builder import FmuBuilder
from pythonfmu.osutil import get_lib_extension, get_platform

from ..errors import BuildError
from ..version import __version__
from .contract import HEADER_NAME
from .modeldesc import model_description

PACKAGE_DIR = Path(__file__).resolve().parents[1]
_IMPORT = re.compile(r"^(\s*(?:from|import)\s+)ncfmu(?=[.\s])", re.MULTILINE)


#: What a controller FMU runs, relative to the package: the controllers and the slave adapter. Only the
#: Python standard library (and the pythonfmu slave API pythonfmu copies into the FMU) is needed at run
#: time; ncfmu's CLI, master, plots, servo models (numpy, scipy, control) stay out.
FMU_RUNTIME = ("__init__.py", "version.py", "errors.py", "ports.py", "controllers/*.py", "fmi/__init__.py",
               "fmi/adapter.py", "fmi/contract.py", "fmi/state.py")


#: The runtime modules compiled with mypyc (bench/README.md, "the controllers compiled as mypyc native classes"): every
#: controller, its bases and the motion they step, as mypyc **native classes** (``controllers/mypyc_compat.py``:
#: serializable, so the FMU states deepcopy and save them as from source), and the lathe program's planner (g7x, gcode,
#: lathe_program: run at configure, not per step). A native class's subclass must be compiled with it (an interpreted
#: subclass's own attributes would be lost by deepcopy): tests/fmi/test_compiled.py holds this list to Controller's
#: subclasses. The rest stay sources: ``errors.py`` (mypyc cannot subclass builtin exceptions), ``geometry.py`` (a
#: compiled ``cached_property`` does not cache into the instance's ``__dict__``, and a compiled dataclass's field types
#: read as the erased runtime types: fmi/state.py checks a restored ``Line``, ``Arc`` or ``ToolMove`` by its declared
#: field types), ``nose.py``, ``rs274.py``, ``mypyc_compat.py`` and ``ports.py`` (configure time only).
COMPILED = ("controllers/base.py", "controllers/cycle.py", "controllers/motion.py", "controllers/sequencer.py",
            "controllers/panel.py", "controllers/limiter.py", "controllers/feed.py", "controllers/contour.py",
            "controllers/gcode.py", "controllers/g7x.py", "controllers/lathe_program.py")
#: Where compiled runtimes are kept, one folder per runtime digest and Python ABI (``NCFMU_CACHE`` overrides the
#: root ``~/.cache/ncfmu``).
COMPILED_CACHE = "compiled"

log = logging.getLogger(__name__)


def _package_files(package_dir: Path = PACKAGE_DIR) -> list[Path]:
    return sorted({p for pattern in FMU_RUNTIME for p in package_dir.glob(pattern)})


def runtime_digest(package_dir: Path = PACKAGE_DIR) -> str:
    """Digest of the runtime files every Python FMU carries (``FMU_RUNTIME``), 12 hex digits: the name of the
    vendored package, ``ncfmu_<digest>``, the same for every Python FMU of a build."""
    h = hashlib.sha256()
    for path in _package_files(package_dir):
        h.update(str(path.relative_to(package_dir)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:12]


def source_digest(script: Path, package_dir: Path = PACKAGE_DIR, compiled: bool = False) -> str:
    """Digest of the model script, every module the FMU carries, the generator of its documentation and whether
    the runtime is compiled (and by which mypyc, for which Python) (12 hex digits)."""
    h = hashlib.sha256()
    for path in [script, *_package_files(package_dir), *PYTHON_FMU_SOURCES, package_dir / "fmi" / "documentation.py"]:
        h.update(str(path.relative_to(path.parent if path == script or package_dir not in path.parents
                                      else package_dir)).encode())
        h.update(path.read_bytes())
    h.update(" ".join(SHIM_LINK).encode())             # how the binary is linked is part of what it is
    if compiled:
        h.update(f"mypyc {_compile_tag()} {' '.join(COMPILED)}".encode())
    return h.hexdigest()[:12]


def _compile_tag() -> str:
    """The Python ABI and the mypyc version a compiled runtime is for (part of its cache folder's name)."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        mypy = version("mypy")
    except PackageNotFoundError:
        mypy = "none"
    return f"{sysconfig.get_config_var('SOABI') or sys.implementation.cache_tag}-mypyc{mypy}-{COMPILE_LAYOUT}"


def _cache_root() -> Path:
    return Path(os.environ.get("NCFMU_CACHE") or Path.home() / ".cache" / "ncfmu")


def compile_unavailable() -> str | None:
    """Why the runtime cannot be compiled here (no mypyc, no C compiler, no setuptools), or None."""
    if importlib.util.find_spec("mypyc") is None:
        return "mypyc is not installed (it comes with mypy, one of ncfmu's dependencies: pip install mypy)"
    if importlib.util.find_spec("setuptools") is None:
        return "setuptools, which mypyc compiles with, is not installed"
    if not any(shutil.which(cc) for cc in (os.environ.get("CC") or "cc", "gcc", "clang")):
        return "no C compiler (cc, gcc or clang) found"
    return None


#: How the controllers are compiled (part of the cache folder's name and of a compiled FMU's digest): mypyc's
#: multi-file mode (one C file per module, and mypyc's runtime in its own files) with the C files compiled in
#: parallel, one job per core. Measured when the layout was chosen (the 11 modules, 2026-12-03): one C file 59 s
#: of gcc CPU, serial; split, 38 s of CPU, which two jobs share.
COMPILE_LAYOUT = "split"

#: The setup script the controllers are compiled with (run in a child Python, in the staging folder): mypyc's
#: ``mypycify`` as ``python -m mypyc`` calls it, but multi-file, and a ``build_ext`` that compiles every C file of
#: every extension in a pool of ``jobs`` threads (setuptools' own ``-j`` runs one job per extension, and the
#: group library is one extension of 29 C files), then links each extension. It prints ``ncfmu-compiled K/N``
#: after each C file, which :func:`compiled_runtime` turns into its progress line.
_SETUP = """
import sys
from concurrent.futures import ThreadPoolExecutor
from threading import Lock

from mypyc.build import mypycify
from setuptools import setup
from setuptools.command.build_ext import build_ext

MODULES, JOBS = {modules!r}, {jobs!r}


class ParallelBuildExt(build_ext):
    def build_extensions(self):
        self.check_extensions_list(self.extensions)
        units = [(ext, source) for ext in self.extensions for source in ext.sources]
        done, lock = [0], Lock()
        print(f"ncfmu-compiled 0/{{len(units)}}", flush=True)

        def compile_one(unit):
            ext, source = unit
            objects = self.compiler.compile([source], output_dir=self.build_temp, macros=ext.define_macros,
                                            include_dirs=ext.include_dirs, debug=self.debug,
                                            extra_postargs=ext.extra_compile_args or [], depends=ext.depends)
            with lock:
                done[0] += 1
                print(f"ncfmu-compiled {{done[0]}}/{{len(units)}}", flush=True)
            return objects

        with ThreadPoolExecutor(JOBS) as pool:
            objects = list(pool.map(compile_one, units))
        at = 0
        for ext in self.extensions:
            mine = [obj for objs in objects[at:at + len(ext.sources)] for obj in objs]
            at += len(ext.sources)
            self.compiler.link_shared_object(
                mine, self.get_ext_fullpath(ext.name), libraries=self.get_libraries(ext),
                library_dirs=ext.library_dirs, runtime_library_dirs=ext.runtime_library_dirs,
                extra_postargs=ext.extra_link_args or [], export_symbols=self.get_export_symbols(ext),
                debug=self.debug, build_temp=self.build_temp, target_lang=self.compiler.detect_language(ext.sources))


setup(name="ncfmu_compiled", ext_modules=mypycify(MODULES, opt_level="3", debug_level="1", multi_file=True),
      cmdclass={{"build_ext": ParallelBuildExt}})
"""

#: The progress line written to standard error while the controllers compile (once per source change).
COMPILING = "compiling the controllers (mypyc, once per source change)"


def _compile_jobs() -> int:
    """C compiler jobs: one per core this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:          # not on Linux
        return max(1, os.cpu_count() or 1)


def _progress(text: str, step: bool = False, final: bool = False) -> None:
    """The compile's progress on standard error: rewritten in place on a terminal; elsewhere (a log) the first
    and the last line only, not one per ``step``."""
    stream = sys.stderr
    if stream.isatty():
        stream.write(f"\r{text}\033[K" + ("\n" if final else ""))
    elif not step:
        stream.write(text + "\n")
    stream.flush()


def _run_setup(src: Path, out: Path, modules: list[str]) -> tuple[int, str]:
    """Run :data:`_SETUP` in ``src`` (extensions into ``out``), writing the progress line; (exit status, log)."""
    import time

    import mypyc
    (src / "build").mkdir(exist_ok=True)
    setup = src / "build" / "setup.py"
    setup.write_text(_SETUP.format(modules=modules, jobs=_compile_jobs()))
    # as ``python -m mypyc`` runs it: mypyc's own folder first, and the working folder (the empty entry) on the
    # path, so mypy finds the staged package there and does not check what it leaves out (serve, ...)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(Path(mypyc.__file__).parents[1]),
                                                       os.environ.get("PYTHONPATH", "")]))
    started = time.monotonic()
    _progress(f"{COMPILING}: generating C ...")
    log: list[str] = []
    with subprocess.Popen([sys.executable, str(setup), "build_ext", "--build-lib", str(out)], cwd=src, env=env,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) as proc:
        assert proc.stdout is not None
        for line in proc.stdout:
            if line.startswith("ncfmu-compiled "):
                _progress(f"{COMPILING}: {line.split()[1]} C files ...", step=True)
            else:
                log.append(line)
        status = proc.wait()
    _progress(f"{COMPILING}: {'done' if status == 0 else 'failed'} in {time.monotonic() - started:.0f} s",
              final=True)
    return status, "".join(log)


def compiled_runtime(package_dir: Path = PACKAGE_DIR) -> Path | None:
    """The runtime's ``COMPILED`` modules compiled with mypyc under the vendored name ``ncfmu_<runtime digest>``:
    a folder holding only the extensions, at the paths they take in an FMU's resources (``ncfmu_<d>/.../*.so``
    and mypyc's group library ``<hash>__mypyc.*.so`` at the top). Compiled once per runtime digest and Python ABI
    and kept in ``~/.cache/ncfmu/compiled/<digest>/<abi>-mypyc<version>-split/``: written into a temporary folder
    beside it and renamed into place, so processes building at once never see a half-written one. While it
    compiles, a progress line on standard error (:data:`COMPILING`). None, with one warning logged, when it cannot
    be compiled here (the FMUs are then built pure: never a BuildError)."""
    digest = runtime_digest(package_dir)
    target = _cache_root() / COMPILED_CACHE / digest / _compile_tag()
    if (target / "COMPLETE").is_file():
        return target
    why = compile_unavailable()
    if why is not None:
        log.warning("ncfmu build: controllers not compiled (%s): building pure-Python FMUs", why)
        return None
    target.parent.mkdir(parents=True, exist_ok=True)
    vendored = f"ncfmu_{digest}"
    with tempfile.TemporaryDirectory(prefix=".compiling-", dir=target.parent) as tmp_name:
        tmp = Path(tmp_name)
        src, out = tmp / "src", tmp / "out"
        for path in _package_files(package_dir):
            copy = src / vendored / path.relative_to(package_dir)
            copy.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, copy)
        status, output = _run_setup(src, out, [f"{vendored}/{m}" for m in COMPILED])
        ext = sysconfig.get_config_var("EXT_SUFFIX") or ".so"
        built = sorted(p.relative_to(out) for p in out.rglob(f"*{ext}")) if out.is_dir() else []
        wanted = {f"{vendored}/{m[:-3]}{ext}" for m in COMPILED}
        if status != 0 or not wanted <= {str(p) for p in built}:
            tail = output.strip()[-400:]
            log.warning("ncfmu build: mypyc could not compile the controllers (exit %s: %s): building pure-Python "
                        "FMUs", status, tail.replace("\n", " | "))
            return None
        (out / "COMPLETE").write_text("\n".join(map(str, built)) + "\n")
        try:
            out.rename(target)
        except OSError:                 # another process renamed its copy into place first: the same content
            if not (target / "COMPLETE").is_file():
                raise
    return target


C_LAYER = Path(__file__).with_name("c")
#: The one FMI 2.0 layer of every ncfmu FMU, over the model interface model.h.
FMI2_LAYER = C_LAYER / "fmi2_functions.c"
#: The Python runtime as a model behind that interface: the Python FMUs' model.
PYTHON_MODEL = C_LAYER / "python_model.c"
#: No -z nodelete: the binary holds a reference to itself exactly while instances made through it live
#: (fmi2_machine.h), so hosts such as ecos may close it under a live instance and hosts that extract the FMU
#: per run unload each copy.
SHIM_LINK = ("-ldl", "-lm", "-lpthread")
CONTRACT_HEADER = C_LAYER / HEADER_NAME
#: What a Python FMU's binaries are compiled from (the FMI 2.0 one and its FMI 3.0 twin's, fmi3.py), and the writer
#: of both its modelDescriptions (modeldesc.py): a change to any rebuilds it.
PYTHON_FMU_SOURCES = (FMI2_LAYER, PYTHON_MODEL, C_LAYER / "model.h", C_LAYER / "fmi2_machine.h",
                      C_LAYER / "fmu_instance.h", CONTRACT_HEADER,
                      C_LAYER / "fmi3_functions.c", Path(__file__).with_name("fmi3.py"),
                      Path(__file__).with_name("modeldesc.py"))


@functools.lru_cache(maxsize=1)
def fmi_headers() -> Path:
    """The official FMI 2.0 C headers, as fmpy ships them."""
    import fmpy
    return Path(fmpy.__file__).parent / "c-code"


def _c_string(text: str) -> str:
    if not re.fullmatch(r"[A-Za-z0-9_.\-]+", text):
        raise BuildError(f"{text!r} cannot be compiled into the FMU's binary (letters, digits, '_', '.', '-' only)")
    return f'"{text}"'


def compile_shim(guid: str, module: str, cls: str) -> bytes:
    """The FMU's binary for this platform (linux64): the FMI layer (fmi2_functions.c) over the Python model
    (python_model.c), with the GUID, the model module and its slave class compiled in. A Python FMU has no
    binary without it, so no compiler is a BuildError: pythonfmu's own library, which would check nothing, is
    never shipped instead."""
    if get_platform() != "linux64":
        raise BuildError(f"Python FMUs are built for linux64 only (the shim's platform), not {get_platform()}")
    defines = [f"-DNCFMU_GUID={_c_string(guid)}", f"-DNCFMU_MODULE={_c_string(module)}",
               f"-DNCFMU_CLASS={_c_string(cls)}"]
    with tempfile.TemporaryDirectory(prefix="ncfmu_shim_") as tmp:
        out = Path(tmp) / "shim.so"
        for cc in ("cc", "gcc", "clang"):
            if shutil.which(cc) is None:
                continue
            proc = subprocess.run([cc, "-shared", "-fPIC", "-O2", "-Wall", *defines, f"-I{fmi_headers()}",
                                   f"-I{C_LAYER}", "-o", str(out), str(FMI2_LAYER), str(PYTHON_MODEL), *SHIM_LINK],
                                  capture_output=True, text=True)
            if proc.returncode != 0:
                raise BuildError(f"compiling the FMU's binary (fmi2_functions.c, python_model.c) with {cc} failed: "
                                 f"{proc.stderr.strip()[:500]}")
            return out.read_bytes()
    raise BuildError("no C compiler (cc, gcc or clang) found: a Python FMU's binary is compiled from "
                     "src/ncfmu/fmi/c/fmi2_functions.c and python_model.c")


def binary_name(model: str) -> str:
    return f"binaries/{get_platform()}/{model}.{get_lib_extension()}"


def has_binary(fmu: Path, model: str) -> bool:
    try:
        with zipfile.ZipFile(fmu) as z:
            return binary_name(model) in z.namelist()
    except (OSError, zipfile.BadZipFile):
        return False


def fmu_version(fmu: Path) -> str | None:
    """The ``version`` attribute the builder recorded in an FMU, or None."""
    try:
        with zipfile.ZipFile(fmu) as z:
            text = z.read("modelDescription.xml").decode()
    except (OSError, KeyError, zipfile.BadZipFile):
        return None
    m = re.search(r'\bversion="([^"]*)"', text)
    return m.group(1) if m else None


def expected_version(script: Path, compiled: bool = False) -> str:
    return f"{__version__}+{source_digest(script, compiled=compiled)}"


def vendored_package(fmu: Path) -> str:
    """The name of the ncfmu copy an FMU carries (``ncfmu_<runtime digest>``, the module prefix it runs under)."""
    with zipfile.ZipFile(fmu) as z:
        names = {n.split("/")[1] for n in z.namelist() if n.startswith("resources/ncfmu_") and n.count("/") >= 2}
    if len(names) != 1:
        raise BuildError(f"{fmu}: carries {sorted(names) or 'no'} ncfmu package(s), not one")
    return names.pop()


def build_fmu(script: Path, dest_dir: Path, compiled: Path | None = None) -> Path:
    """Build one FMU from a model script into ``dest_dir``; return the FMU's path. ``compiled``: a folder
    :func:`compiled_runtime` made, whose extensions the FMU ships beside the sources (None: pure Python)."""
    if not FmuBuilder.has_binary():
        where = sys.modules[FmuBuilder.__module__].__file__
        raise BuildError(f"pythonfmu at {Path(where).parent if where else FmuBuilder.__module__} has no binary for "
                         f"{get_platform()}: reinstall pythonfmu")
    script = Path(script).resolve()
    model = script.stem
    digest = source_digest(script, compiled=compiled is not None)
    vendored = f"ncfmu_{runtime_digest()}"
    module = f"{model}_{digest}"
    dest_dir = Path(dest_dir)
    dest_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="ncfmu_build_") as tmp_name:
        tmp = Path(tmp_name)
        stage = tmp / "stage"
        stage.mkdir()
        for path in _package_files():
            copy = stage / vendored / path.relative_to(PACKAGE_DIR)
            copy.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, copy)
        if compiled is not None:
            for ext in sorted(compiled.rglob("*.so")):
                rel = ext.relative_to(compiled)
                if rel.parts[0].startswith("ncfmu_") and rel.parts[0] != vendored:
                    raise BuildError(f"{compiled}: compiled for {rel.parts[0]}, not {vendored}")
                (stage / rel).parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(ext, stage / rel)
        text = script.read_text()
        if not re.search(rf"^class {model}\(\s*Fmi2Slave\s*\)\s*:", text, re.MULTILINE):
            raise BuildError(f"{script}: needs a line 'class {model}(Fmi2Slave):' (pythonfmu finds the class by it)")
        (stage / f"{module}.py").write_text(_IMPORT.sub(rf"\g<1>{vendored}", text))
        out = tmp / "out"
        loaded = set(sys.modules)
        try:
            group = sorted(stage.glob("*.so"))          # mypyc's group library, imported by the extensions
            built = FmuBuilder.build_FMU(stage / f"{module}.py", dest=out,
                                         project_files=[stage / vendored, *group])
            logic = getattr(importlib.import_module(module), model).logic_class
        except Exception as err:  # pythonfmu raises plain exceptions; say which script failed
            raise BuildError(f"pythonfmu could not build {script.name}: {err}") from err
        finally:
            if str(stage) in sys.path:
                sys.path.remove(str(stage))
        try:
            target = dest_dir / f"{logic.MODEL_NAME}.fmu"
            _rewrite(built, target, logic, f"{__version__}+{digest}", module, model)
        finally:
            # pythonfmu imported the script (and the vendored package) from the stage, which is deleted below:
            # forget what this build imported, so the package an FMU of this build runs in this process is the
            # FMU's own copy (the next build of the same package name imports its own stage's)
            for name in set(sys.modules) - loaded:
                if name == module or name.split(".")[0] == vendored or name.endswith("__mypyc"):
                    del sys.modules[name]
    if not has_binary(target, logic.MODEL_NAME):
        target.unlink()
        raise BuildError(f"{script.name}: the built FMU lacks {binary_name(logic.MODEL_NAME)}")
    return target


def python_runtime_record() -> str:
    """``resources/ncfmu_python.txt``: the libpython this FMU was built with (full path, then soname) and its
    home (``sys.base_prefix``), which the binary loads and starts in a native host (see python_model.c;
    ``NCFMU_LIBPYTHON`` overrides)."""
    import sysconfig
    libdir, soname = sysconfig.get_config_var("LIBDIR") or "", sysconfig.get_config_var("INSTSONAME") or ""
    if not sysconfig.get_config_var("Py_ENABLE_SHARED") or not soname:
        return ""                  # a static Python: native hosts need NCFMU_LIBPYTHON
    return f"{Path(libdir) / soname}\n{soname}\n{sys.base_prefix}\n"


RUNTIME_HTML = """<h2>Runtime requirements</h2>
<p>Platform: linux64 (x86-64 Linux) only; the binary is compiled by <code>ncfmu build</code> from ncfmu's
FMI layer <code>fmi2_functions.c</code> over its Python model <code>python_model.c</code> and is the only one
this FMU lists.</p>
<p>This FMU runs Python code (the controller and pythonfmu's slave API, both inside the FMU's resources):
it needs the CPython it was built with, {version}, with its shared library, and only its standard library.
In a Python host (fmpy, ncfmu) it uses the host's interpreter. In a native host (fmusim, ecos, libcosim) the
FMU's binary loads the runtime itself: <code>$NCFMU_LIBPYTHON</code> (a path or soname) when set, else the
library recorded at build time in <code>resources/ncfmu_python.txt</code> (<code>{record}</code>), then its
soname through the system's library search. If none loads, fmi2Instantiate fails with one message saying so.
The interpreter is started once per process and never finalised.</p>"""


def _rewrite(src: Path, target: Path, logic, version: str, module: str, cls: str) -> None:
    """The FMU as shipped: pythonfmu's model description enriched, our binary, no other platform's."""
    from .documentation import fmu_html
    binary = f"binaries/linux64/{cls}.so"
    with zipfile.ZipFile(src) as zin:
        written = zin.read("modelDescription.xml")
        guid = re.search(rb'\bguid="([^"]*)"', written)
        if guid is None:
            raise BuildError(f"{cls}: pythonfmu's modelDescription has no guid")
        description = model_description(logic, "2.0", guid.group(1).decode(), version, pythonfmu_xml=written)
        compiled = compile_shim(guid.group(1).decode(), module, cls)      # before anything is written
        record = python_runtime_record()
        extra = RUNTIME_HTML.format(version=".".join(map(str, sys.version_info[:2])),
                                    record=", ".join(record.split()) or "none: a static Python")
        partial = target.with_suffix(".fmu.part")
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as zout:
            for item in zin.infolist():
                if item.filename.startswith("binaries/"):
                    continue              # pythonfmu's export libraries: our binary (below) replaces them
                if item.filename == "modelDescription.xml":
                    zout.writestr(item.filename, description)
                    zout.writestr(binary, compiled)
                    zout.writestr("documentation/index.html", fmu_html(description, logic, extra=extra))
                    zout.writestr("resources/ncfmu_python.txt", record)
                else:
                    zout.writestr(item.filename, zin.read(item.filename))
    partial.replace(target)


def model_scripts(models_dir: Path) -> list[Path]:
    """The model script of every Python model of the catalogue, in its order; a model without its script, or a
    script of no model, is a BuildError naming it."""
    from ..catalogue import python_models
    scripts = {p.stem: p for p in Path(models_dir).glob("*.py") if not p.name.startswith("_")}
    missing = [name for name in python_models() if name not in scripts]
    if missing:
        raise BuildError(f"{models_dir}: no model script for {', '.join(missing)} (models/<MODEL_NAME>.py)")
    unknown = sorted(set(scripts) - set(python_models()))
    if unknown:
        raise BuildError(f"{models_dir}: {', '.join(unknown)}.py names no controller of ncfmu.controllers")
    return [scripts[name] for name in python_models()]


#: The file in a build's output folder (``fmus/``) that remembers which kind of Python FMUs it was asked for,
#: ``compiled`` or ``pure``, so the next build that is not told (``ncfmu run``, ``sweep``, ``serve``, ``validate``)
#: keeps that kind instead of rebuilding the other one.
KIND_FILE = "ncfmu-build-kind"
KINDS = ("compiled", "pure")


def built_kind(dest_dir: Path) -> str | None:
    """The kind the last build into ``dest_dir`` was asked for (:data:`KIND_FILE`), or None (none recorded)."""
    try:
        kind = (Path(dest_dir) / KIND_FILE).read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError):
        return None
    return kind if kind in KINDS else None


def chosen_pure(dest_dir: Path, pure: bool | None) -> bool:
    """Whether a build into ``dest_dir`` is pure: as asked (True/False), else (None) the kind recorded there,
    else compiled, the default."""
    return built_kind(dest_dir) == "pure" if pure is None else pure


def remember_kind(dest_dir: Path, pure: bool) -> None:
    """Record the kind asked for in ``dest_dir`` (only when it changes: a build writes nothing that is right)."""
    kind = "pure" if pure else "compiled"
    if built_kind(dest_dir) != kind:
        from ..files import write_atomic
        write_atomic(Path(dest_dir) / KIND_FILE, f"{kind}\n".encode())


def build_all(models_dir: Path, dest_dir: Path, only_stale: bool = False, pure: bool = False) -> list[Path]:
    """Build every model script (pythonfmu) and every native model (C); with ``only_stale`` skip FMUs
    built from the same source. The Python FMUs ship the runtime compiled (:func:`compiled_runtime`, once for
    all of them) unless ``pure`` or it cannot be compiled here (then pure, one warning logged)."""
    from .native import build_native_fmu, native_models
    compiled: Path | None = None
    compile_here = not pure and compile_unavailable() is None
    built = []
    for native in native_models():
        target = Path(dest_dir) / f"{native.name}.fmu"
        if (only_stale and target.exists() and fmu_version(target) == native.version()
                and has_binary(target, native.name)):
            built.append(target)
            continue
        built.append(build_native_fmu(native, dest_dir))
    for script in model_scripts(models_dir):
        target = Path(dest_dir) / f"{script.stem}.fmu"
        if (only_stale and target.exists() and fmu_version(target) == expected_version(script, compile_here)
                and has_binary(target, script.stem)):
            built.append(target)
            continue
        if not pure and compiled is None:
            compiled = compiled_runtime()
            if compiled is None:
                pure = True
        built.append(build_fmu(script, dest_dir, compiled=compiled))
    return built
