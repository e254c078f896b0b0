"""Foreign FMUs for the tests: models no one on the project wrote in ncfmu's code, built from C in the test session.

``tests/foreign/`` holds their sources -- a small FMI 2.0 co-simulation frame (``frame2.c``) on the FMI headers
that come with fmpy, a model file each and a hand-written modelDescription -- and :func:`build` compiles each
into an FMU (binaries/linux64 plus its sources) with the system C compiler. They stand for a user's plant:

- ``PlantAxis``: a feed axis in mm (pos_cmd, vel_ff -> pos, vel, following_error, in_position);
- ``PlantAxisMetre``: the same axis in metres (m, m/s);
- ``PlantAxisBare``: the same axis in mm without any unit declared;
- ``CrashingAxis``: the PlantAxis with a bug: at ``crash_at`` (s) it dies in fmi2DoStep or fmi2GetReal
  (``crash_in`` 0 or 1) by SIGSEGV, abort() or exit(3) (``crash_how`` 1, 2, 3) -- the process that runs it with it;
- ``Countdown``: counts seconds, ends the experiment at ``end_at`` (fmi2Discard + fmi2Terminated), an output in min;
- ``Stairs``: the Countdown as the Reference-FMUs' Stair ends: the step that reaches ``end_at`` is made whole, then
  fmi2Discard + fmi2Terminated (fmi2LastSuccessfulTime at the step's end);
- ``Feedthrough``: inputs to outputs per type (Real with a declaredType in s and one in mm, Integer, Boolean),
  a gain with min/max, a String parameter;
- ``PlantAxis3``, ``Countdown3``, ``Stairs3``, ``Feedthrough3``, ``CrashingAxis3``: the same models as FMI 3.0
  co-simulation FMUs (``frame3.c``; Float64, Int32, Boolean, String; CrashingAxis3 crashes in fmi3DoStep only).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path

SOURCES = Path(__file__).resolve().parent / "foreign"


@dataclass(frozen=True)
class Foreign:
    name: str                  # modelName and modelIdentifier
    model_c: str
    xml: str
    defines: dict[str, str]
    substitutions: dict[str, str]
    fmi: int = 2               # the FMI version of its frame: 2 (frame2.c) or 3 (frame3.c + stubs3.c)
    includes: tuple[str, ...] = ()   # other sources its model file includes


def _plant(name: str, scale: float, length: str | None, model_c: str = "plant_axis.c", extra: str = "",
           defines: dict[str, str] | None = None) -> Foreign:
    velocity = None if length is None else f"{length}/s"
    units = "" if length is None else "".join(
        f'<Unit name="{u}"><BaseUnit {base}/></Unit>'
        for u, base in ((length, 'm="1"' + ("" if scale == 1e-3 else ' factor="0.001"')),
                        (velocity, 'm="1" s="-1"' + ("" if scale == 1e-3 else ' factor="0.001"')),
                        ("1/s", 's="-1"'), ("s", 's="1"')))
    units = units and f"<UnitDefinitions>{units}</UnitDefinitions>"

    def attr(unit: str | None) -> str:
        return "" if unit is None else f' unit="{unit}"'
    return Foreign(name, model_c, "plant_axis.xml", {"SCALE": repr(scale), **(defines or {})},
                   {"@NAME@": name, "@EXTRA@": extra, "@UNITS@": units, "@LEN@": attr(length), "@VEL@": attr(velocity),
                    "@PER_S@": attr(None if length is None else "1/s"), "@S@": attr(None if length is None else "s"),
                    "@VEL_MAX@": repr(500.0 * scale), "@BAND@": repr(0.005 * scale)},
                   includes=() if model_c == "plant_axis.c" else ("plant_axis.c",))


#: CrashingAxis's variables beyond PlantAxis's (tests/foreign/crashing_axis.c)
_CRASH_VARIABLES = """
    <ScalarVariable name="crash_at" valueReference="10" causality="parameter" variability="fixed" initial="exact"
        description="the simulated time the FMU crashes at"><Real unit="s" start="1"/></ScalarVariable>
    <ScalarVariable name="crash_how" valueReference="0" causality="parameter" variability="fixed" initial="exact"
        description="1: SIGSEGV, 2: abort(), 3: exit(3)"><Integer start="1" min="1" max="3"/></ScalarVariable>
    <ScalarVariable name="crash_in" valueReference="1" causality="parameter" variability="fixed" initial="exact"
        description="0: fmi2DoStep, 1: fmi2GetReal"><Integer start="0" min="0" max="1"/></ScalarVariable>"""

#: the same as FMI 3.0 variables (tests/foreign/frame3.c: Float64 from 1, Int32 from 101); it crashes in fmi3DoStep
_CRASH_VARIABLES3 = """
    <Float64 name="crash_at" valueReference="11" causality="parameter" variability="fixed" unit="s" start="1"/>
    <Int32 name="crash_how" valueReference="101" causality="parameter" variability="fixed" start="1" min="1"
        max="3"/>
    <Int32 name="crash_in" valueReference="102" causality="parameter" variability="fixed" start="0" min="0"
        max="0"/>"""

# the Countdown made whole at its last step (-DWHOLE_STEP), under a name and GUID of its own
_STAIRS = {'Countdown"': 'Stairs"', 'Countdown3"': 'Stairs3"', "countdown001": "stairs000001",
           "countdown3fm": "stairs3fmu00"}

FOREIGN = {f.name: f for f in (
    _plant("PlantAxis", 1.0, "mm"),
    _plant("PlantAxisMetre", 1e-3, "m"),
    _plant("PlantAxisBare", 1.0, None),
    _plant("CrashingAxis", 1.0, "mm", "crashing_axis.c", _CRASH_VARIABLES, {"GET_HOOK": "crash_in_get"}),
    Foreign("Countdown", "countdown.c", "countdown.xml", {}, {}),
    Foreign("Feedthrough", "feedthrough.c", "feedthrough.xml", {}, {}),
    Foreign("PlantAxis3", "plant_axis.c", "plant_axis3.xml", {"SCALE": "1.0"}, {"@EXTRA@": ""}, 3),
    Foreign("CrashingAxis3", "crashing_axis.c", "plant_axis3.xml", {"SCALE": "1.0"},
            {'PlantAxis3"': 'CrashingAxis3"', "plantaxis3fm": "crashaxis3fm", "@EXTRA@": _CRASH_VARIABLES3}, 3,
            ("plant_axis.c",)),
    Foreign("Countdown3", "countdown.c", "countdown3.xml", {}, {}, 3),
    Foreign("Stairs", "countdown.c", "countdown.xml", {"WHOLE_STEP": "1"}, _STAIRS),
    Foreign("Stairs3", "countdown.c", "countdown3.xml", {"WHOLE_STEP": "1"}, _STAIRS, 3),
    Foreign("Feedthrough3", "feedthrough.c", "feedthrough3.xml", {}, {}, 3),
)}


def fmi_headers() -> Path:
    import fmpy
    return Path(fmpy.__file__).parent / "c-code"


def model_description(f: Foreign) -> str:
    text = (SOURCES / f.xml).read_text()
    if "@GUID@" in text:
        f.substitutions.setdefault("@GUID@", "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"foreign:{f.name}")) + "}")
    for key, value in f.substitutions.items():
        text = text.replace(key, value)
    return text


def build_one(f: Foreign, dest: Path) -> Path:
    """Compile ``f`` and pack it as ``dest/<name>.fmu``."""
    import re
    md = model_description(f)
    guid = re.search(r'(?:guid|instantiationToken)="([^"]+)"', md)
    assert guid is not None
    stage = dest / f"{f.name}.stage"
    shutil.rmtree(stage, ignore_errors=True)
    platform = "linux64" if f.fmi == 2 else "x86_64-linux"      # FMI 3.0 names platforms by tuple
    (stage / "binaries" / platform).mkdir(parents=True)
    (stage / "sources").mkdir()
    (stage / "modelDescription.xml").write_text(md)
    frame = ("frame2.c",) if f.fmi == 2 else ("frame3.c", "stubs3.c")
    for src in (*frame, "model.h", f.model_c, *f.includes):
        shutil.copy(SOURCES / src, stage / "sources" / src)
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc") or "cc"
    defines = {"MODEL_GUID": f'"{guid.group(1)}"', **f.defines}
    command = [cc, "-shared", "-fPIC", "-O2", "-std=c99", "-D_DEFAULT_SOURCE", "-Wall", "-Werror", f"-I{fmi_headers()}",
               f"-I{stage / 'sources'}", *(f"-D{k}={v}" for k, v in defines.items()),
               *(str(stage / "sources" / src) for src in frame), str(stage / "sources" / f.model_c),
               "-o", str(stage / "binaries" / platform / f"{f.name}.so"), "-lm"]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(f"compiling {f.name} failed:\n{done.stderr}")
    target = dest / f"{f.name}.fmu"
    with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as z:
        for path in sorted(stage.rglob("*")):
            if path.is_file():
                z.write(path, path.relative_to(stage).as_posix())
    shutil.rmtree(stage)
    return target


def build(dest: Path) -> dict[str, Path]:
    """Every foreign FMU built into ``dest``: name -> path."""
    dest.mkdir(parents=True, exist_ok=True)
    return {name: build_one(f, dest) for name, f in FOREIGN.items()}


def packed(system, fmus: dict[str, Path], dest: Path) -> Path:
    """``system`` (an ncfmu System whose components name models of ``fmus`` or ncfmu's own) packed as
    ``dest/<system>.ssp``: the SSD and .ssv files as ncfmu writes them, each model's FMU from ``fmus`` or the
    project's ``fmus/``."""
    from ncfmu.cosim.ssp import pack, write_system
    folder = write_system(system, dest / "src")
    models = dest / "fmus"
    models.mkdir(parents=True, exist_ok=True)
    own = Path(__file__).resolve().parents[1] / "fmus"
    for comp in system.components:
        source = fmus.get(comp.model, own / f"{comp.model}.fmu")
        shutil.copy(source, models / f"{comp.model}.fmu")
    return pack(folder, models, dest / f"{system.name}.ssp")


def with_plant(system_name: str, model: str, scale: float = 1.0, axes=("x_axis", "z_axis"), drop=()):
    """A shipped system with its servo axes ``axes`` replaced by the foreign ``model`` (start position in the
    model's length unit: ``scale`` mm), the connections named in ``drop`` left out."""
    from ncfmu.systems import get_system
    system = get_system(system_name)
    for comp in system.components:
        if comp.name in axes:
            comp.model = model
            comp.parameters = {"pos_start": comp.parameters["pos_start"] * scale}
            comp.connectors = []          # the user's SSD declares what their FMU has; here: nothing
    system.connections = [c for c in system.connections if str(c) not in drop]
    return system
