"""Build native (C) FMUs: the ServoAxis and the SpindleDrive.

A native FMU carries its C sources (``sources/``, listed in the modelDescription's ``SourceFiles`` so
any FMI tool, fmpy included, can compile it for its platform) and a linux64 binary compiled here by
fmpy's CMake build (:func:`fmpy.build.build_platform_binary`) with the system C compiler. It needs no
Python at run time.

What is written where (one home per fact):

- the variables, their start values and their rules come from the model's Python ports
  (:class:`~ncfmu.ports.Port`) and are generated into ``model_vars.h``;
- the FMI layer is ``fmi/c/fmi2_functions.c`` (the one layer of every ncfmu FMU, the Python FMUs' too) with the
  state machine of ``fmi/c/fmi2_machine.h``, over the model interface ``fmi/c/model.h``, which
  ``fmi/c/native_model.c`` implements for table-driven native models;
- the equations are the model's own C file (``servo/native/servo_model.c``): section 2 of ``model.h``.
"""

from __future__ import annotations

import contextlib
import hashlib
import html
import io
import math
import os
import re
import shutil
import sys
import tempfile
import uuid
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import BuildError
from ..version import __version__
from .modeldesc import model_description as write_model_description

if TYPE_CHECKING:
    from ..controllers.base import Controller

C_LAYER = Path(__file__).with_name("c")
PACKAGE_DIR = Path(__file__).resolve().parents[1]
#: What a native FMU carries of the FMI layer (its sources/), beside the model's C file and model_vars.h.
LAYER_SOURCES = ("fmi2_functions.c", "native_model.c")
LAYER_HEADERS = ("fmi2_machine.h", "model.h", "fmu_instance.h")


@dataclass(frozen=True)
class NativeModel:
    """A native FMU: its Python logic (ports, description, the executable specification) and its C file."""

    logic: type[Controller]
    model_c: Path
    #: Python files whose content defines the FMU (ports, design): a change rebuilds it.
    defined_by: tuple[Path, ...]
    #: C headers the model includes beside the FMI layer's (``NATIVE_HEADERS``), shipped in ``sources/``.
    headers: tuple[Path, ...] = ()

    @property
    def name(self) -> str:
        return self.logic.MODEL_NAME

    def sources(self) -> dict[str, bytes]:
        return {**{name: (C_LAYER / name).read_bytes() for name in (*LAYER_HEADERS, *LAYER_SOURCES)},
                **{h.name: h.read_bytes() for h in self.headers},
                self.model_c.name: self.model_c.read_bytes()}

    def digest(self) -> str:
        h = hashlib.sha256()
        for name, data in sorted(self.sources().items()):
            h.update(name.encode())
            h.update(data)
        # the FMI 3.0 twin (fmi3.py) is built from the same version: its layer is part of what it is, and so is the
        # writer of both modelDescriptions (modeldesc.py)
        fmi3 = (C_LAYER / "fmi3_functions.c", Path(__file__).with_name("fmi3.py"))
        for path in (*self.defined_by, Path(__file__), *fmi3, Path(__file__).with_name("modeldesc.py")):
            h.update(path.read_bytes())
        return h.hexdigest()[:12]

    def version(self) -> str:
        return f"{__version__}+{self.digest()}"


def native_models() -> list[NativeModel]:
    """The catalogue's native models, each with its C source and what it is defined by."""
    from ..catalogue import models, native_models
    # the design files are named by their paths, not imported: servo/model.py imports python-control (~1.3 s),
    # which every run's staleness check would pay; only an actual build needs it. fmi/documentation.py writes
    # its documentation: a change there rebuilds it too
    out = []
    for name in native_models():
        logic = models()[name]
        module = Path(sys.modules[logic.__module__].__file__ or "")
        defined_by = tuple(module.parent / f for f in logic.NATIVE_DEFINED_BY)
        out.append(NativeModel(logic, module.parent / logic.NATIVE_SOURCE,
                               (module, *defined_by, PACKAGE_DIR / "ports.py",
                                PACKAGE_DIR / "fmi" / "documentation.py"),
                               tuple(module.parent / h for h in logic.NATIVE_HEADERS)))
    return out


# -- generated files ------------------------------------------------------------------------------
def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _c_double(x: float | None) -> str:
    return "0.0" if x is None else repr(float(x))


def vars_header(m: NativeModel, guid: str) -> str:
    """``model_vars.h``: value references (the port's index), and the variable table from the ports."""
    ports = m.logic.PORTS
    for port in ports:
        if not re.fullmatch(r"[A-Za-z_]\w*", port.name) or port.type == "String" or port.allowed is not None:
            raise BuildError(f"{m.name}.{port.name}: a native FMU supports plain Real/Integer/Boolean names "
                             "with a range (no list of allowed values) only")
    kinds = {"Real": "V_REAL", "Integer": "V_INTEGER", "Boolean": "V_BOOLEAN"}
    causalities = {"parameter": "V_PARAMETER", "input": "V_INPUT", "output": "V_OUTPUT"}
    lines = ["/* Generated by ncfmu.fmi.native from the model's Python ports: do not edit. */",
             "#ifndef NCFMU_MODEL_VARS_H", "#define NCFMU_MODEL_VARS_H", "",
             f"#define MODEL_IDENTIFIER {_c_string(m.name)}", f"#define MODEL_GUID {_c_string(guid)}",
             f"#define MODEL_BUILD {_c_string(m.version())}", f"#define NVARS {len(ports)}u", "", "enum {"]
    lines += [f"    VR_{p.name} = {vr}," for vr, p in enumerate(ports)]
    lines += ["};", "", "#ifdef NCFMU_VAR_TABLE", "static const VarInfo MODEL_VARS[NVARS] = {"]
    for p in ports:
        start = p.default()
        start = float(start) if not isinstance(start, bool) else (1.0 if start else 0.0)
        rule = p.rule() if p.causality == "parameter" else ""
        tunable = 1 if p.causality == "parameter" and p.variability == "tunable" else 0
        lines.append(f"    {{{_c_string(p.name)}, {kinds[p.type]}, {causalities[p.causality]}, {tunable}, "
                     f"{_c_double(start)}, {int(p.min is not None)}, {int(p.max is not None)}, "
                     f"{int(p.min_exclusive)}, {_c_double(p.min)}, {_c_double(p.max)}, {_c_string(rule)}}},")
    lines += ["};", "#endif", "", "#endif", ""]
    return "\n".join(lines)


def model_description(m: NativeModel, guid: str, fmi_version: str = "2.0") -> bytes:
    """The modelDescription (:func:`ncfmu.fmi.modeldesc.model_description`), naming the C sources it carries."""
    return write_model_description(m.logic, fmi_version, guid, m.version(),
                                   native_sources=(*LAYER_SOURCES, m.model_c.name))


def build_description(m: NativeModel) -> str:
    """``sources/buildDescription.xml`` (the FMI 3.0 form, which FMI 2.0 tools that compile sources also read)."""
    files = "\n".join(f'      <SourceFile name="{n}"/>' for n in (*LAYER_SOURCES, m.model_c.name))
    how = ("C11 with -O2 (fmi2FreeInstance drops the library's reference to itself in a tail call); link with -lm "
           "-lpthread -ldl")
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiBuildDescription fmiVersion="3.0">
  <BuildConfiguration modelIdentifier="{m.name}" description="{how}">
    <SourceFileSet language="C11">
{files}
    </SourceFileSet>
    <Library name="m"/>
    <Library name="pthread"/>
    <Library name="dl"/>
  </BuildConfiguration>
</fmiBuildDescription>
"""


def _design_html(m: NativeModel, stage: Path) -> str:
    """Design figures of the default parameters, and a Bode plot, for the FMU's documentation."""
    from ..servo.axis import ServoAxis
    from ..servo.bode import bode_design
    from ..servo.model import MIN_PHASE_MARGIN
    from ..servo.spindle import SpindleDrive
    logic = m.logic()
    if isinstance(logic, SpindleDrive):
        return _spindle_design_html(m, logic, stage)
    assert isinstance(logic, ServoAxis), "the native models are servo axes and spindle drives"
    d, p = logic.design, logic.p
    bode = bode_design(p)
    velocity, position = bode.loops
    rows = [("velocity loop: phase margin", f"{d.velocity_margin:.1f} deg"),
            ("velocity loop: crossover", f"{d.velocity_crossover:.1f} rad/s"),
            ("velocity loop: gain margin", velocity.gain_margin_text().removeprefix("GM ")),
            ("velocity loop: closed-loop bandwidth (-3 dB)", f"{d.velocity_bandwidth:.1f} rad/s"),
            ("position loop: phase margin", f"{d.position_margin:.1f} deg"),
            ("position loop: crossover", f"{d.position_crossover:.1f} rad/s"),
            ("position loop: gain margin", position.gain_margin_text().removeprefix("GM ")),
            ("position loop: closed-loop bandwidth (-3 dB)", f"{d.position_bandwidth:.1f} rad/s"),
            ("current loop: corner 1/tau_current", f"{1.0 / p.tau_current:.0f} rad/s")]
    figure = ""
    if _bode_png(stage, "bode_figure", p) is not None:
        figure = (f'<p><img src="bode.png" alt="Bode plot of the open velocity and position loops from '
                  f'{bode.band[0]:.1f} to {bode.band[1]:.0f} rad/s, with their margins"></p>\n'
                  f"<p>The band that matters: from a decade below the position loop's closed-loop bandwidth "
                  f"({bode.band[0]:.1f} rad/s) to a decade above the current loop's corner ({bode.band[1]:.0f} "
                  "rad/s). Dotted: each loop's gain crossover, its phase margin the bar up from -180 deg; dashed: "
                  "the phase crossover, the gain margin the bar up to 0 dB.</p>")
    return _design_section(m, (
        "At fmi2ExitInitializationMode the FMU computes the phase margins of both loops from the parameters\n"
        "(the continuous models of ncfmu.servo.model) and refuses, with fmi2Error naming the parameter, a closed loop\n"
        f"that is unstable or has less than {MIN_PHASE_MARGIN:g} deg phase margin."), rows, figure)


def _spindle_design_html(m: NativeModel, logic, stage: Path) -> str:
    """The SpindleDrive's design figures (default parameters) and what its ramps take."""
    from ..servo.spindle_model import MIN_PHASE_MARGIN
    d, p = logic.design, logic.p
    accel = (logic.torque_max - logic.tau_coulomb) / p.J            # rad/s^2 while the torque limit acts
    base = logic.power_max / logic.torque_max * 60.0 / (2.0 * math.pi)
    rows = [("speed loop: phase margin", f"{d.phase_margin:.1f} deg"),
            ("speed loop: crossover", f"{d.crossover:.1f} rad/s"),
            ("speed loop: gain margin", "infinite (the phase never reaches -180 deg)" if not math.isfinite(
                d.gain_margin) else f"{20 * math.log10(d.gain_margin):.1f} dB"),
            ("speed loop: closed-loop bandwidth (-3 dB)", f"{d.bandwidth:.1f} rad/s"),
            ("current loop: corner 1/tau_current", f"{1.0 / p.tau_current:.0f} rad/s"),
            ("acceleration at the torque limit, (torque_max - tau_coulomb) / J",
             f"{accel * 60.0 / (2.0 * math.pi):.0f} rev/min/s"),
            ("base speed power_max / torque_max (constant power above it)", f"{base:.0f} rev/min")]
    figure = ""
    bode = _bode_png(stage, "spindle_bode_figure", p)
    if bode is not None:
        figure = (f'<p><img src="bode.png" alt="Bode plot of the open speed loop from {bode.band[0]:.1f} to '
                  f'{bode.band[1]:.0f} rad/s, with its phase margin"></p>\n'
                  f"<p>From a decade below the PI zero ({bode.band[0] * 10:.0f} rad/s) to a decade above the current "
                  "loop's corner. Dotted: the gain crossover, the phase margin the bar up from -180 deg.</p>")
    return _design_section(m, (
        "At fmi2ExitInitializationMode the FMU computes the speed loop's phase margin from the parameters (the "
        "continuous\nmodels of ncfmu.servo.spindle_model) and refuses, with fmi2Error naming speed_bandwidth, a loop "
        f"that is unstable or\nhas less than {MIN_PHASE_MARGIN:g} deg phase margin."), rows, figure)


def _bode_png(stage: Path, figure_of: str, p):
    """documentation/bode.png of the FMU being staged, drawn by ``servo.bode.<figure_of>(p)``; the Bode data it
    was drawn from, or None without matplotlib (optional: the figures stay, the plot is left out)."""
    try:
        from ..servo import bode as plots
        fig, bode = getattr(plots, figure_of)(p)
        out = io.BytesIO()
        fig.savefig(out, format="png", dpi=80)
        import matplotlib.pyplot as plt
        plt.close(fig)
    except ImportError:
        return None
    (stage / "documentation").mkdir(exist_ok=True)
    (stage / "documentation" / "bode.png").write_bytes(out.getvalue())
    return bode


def _design_section(m: NativeModel, design: str, rows: list[tuple[str, str]], figure: str) -> str:
    """A native FMU's design section (what it refuses, its figures, its plot) and its runtime requirements."""
    table = "\n".join(f"<tr><td>{a}</td><td>{html.escape(b)}</td></tr>" for a, b in rows)
    c_files = ", ".join(sorted(name for name in m.sources() if name.endswith(".c")))
    return f"""<h2>Design (python-control, default parameters)</h2>
<p>{design}</p>
<table>{table}</table>
{figure}
<h2>Runtime requirements</h2>
<p>None: a C binary (linux64, built with the system C compiler) linked against the C library and libm only;
the C sources are in <code>sources/</code> ({c_files}; C11, link with -lm -lpthread -ldl), so
<code>fmpy.build.build_platform_binary</code> or any FMI tool that compiles sources builds it for another
platform.</p>"""


# -- the build ------------------------------------------------------------------------------------
@contextlib.contextmanager
def _output_to(log: Path) -> Iterator[None]:
    """Send this process's stdout and stderr (file descriptors 1 and 2) to ``log`` meanwhile.

    fmpy.build.build_platform_binary runs cmake with subprocess.check_call, which inherits our stdout: a
    run that builds the servo would print CMake's chatter between its summary lines. Narrowest fix: the
    descriptors, for the duration of the call; a failure shows the log's tail instead.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    with open(log, "wb") as f:
        os.dup2(f.fileno(), 1)
        os.dup2(f.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
def build_native_fmu(m: NativeModel, dest_dir: Path) -> Path:
    """Build the native FMU ``m`` into ``dest_dir``; return its path."""
    from fmpy.build import build_platform_binary

    from .documentation import fmu_html
    if shutil.which("cmake") is None:
        raise BuildError(f"{m.name}: building the native FMU needs cmake (pip install cmake) and a C compiler")
    guid = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"ncfmu:{m.name}:{m.version()}")) + "}"
    dest_dir = Path(dest_dir)
    dest_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="ncfmu_native_") as tmp:
        stage = Path(tmp) / "fmu"
        sources = stage / "sources"
        sources.mkdir(parents=True)
        for name, data in m.sources().items():
            (sources / name).write_bytes(data)
        (sources / "model_vars.h").write_text(vars_header(m, guid))
        (sources / "buildDescription.xml").write_text(build_description(m))
        md = model_description(m, guid)
        (stage / "modelDescription.xml").write_bytes(md)
        # The model needs no resources, but fmi2Instantiate checks the host's fmuResourceLocation names an
        # existing folder (as every ncfmu FMU does): the folder is there, with a note of the build.
        (stage / "resources").mkdir()
        (stage / "resources" / "build.txt").write_text(f"{m.name} {m.version()}\nGUID {guid}\n")
        (stage / "documentation").mkdir()
        extra = _design_html(m, stage)
        (stage / "documentation" / "index.html").write_bytes(fmu_html(md, m.logic, "its C sources", extra))
        log = Path(tmp) / "cmake.log"
        try:
            # The FMI headers come with fmpy's CMake project; the model needs libm (exp, atan2, nearbyint), the
            # layer libdl (it holds itself loaded while its instances live: fmi2_machine.h; no -z nodelete).
            (Path(tmp) / "build").mkdir()
            with _output_to(log):
                build_platform_binary(stage, build_dir=Path(tmp) / "build",
                                      cmake_options={"CMAKE_C_STANDARD_LIBRARIES:STRING": "-lm -lpthread -ldl",
                                                     "CMAKE_C_FLAGS:STRING": "-O2 -std=c11 -D_DEFAULT_SOURCE"})
        except Exception as err:  # fmpy raises CalledProcessError; the compiler's messages are in the log
            tail = log.read_text(errors="replace").strip().splitlines()[-30:] if log.exists() else []
            raise BuildError(f"{m.name}: compiling the native FMU failed: {err}\n" + "\n".join(tail)) from err
        target = dest_dir / f"{m.name}.fmu"
        partial = target.with_suffix(".fmu.part")
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as z:
            for path in sorted(stage.rglob("*")):
                if path.is_file():
                    z.write(path, path.relative_to(stage).as_posix())
        partial.replace(target)
    return target
