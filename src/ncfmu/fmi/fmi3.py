"""FMI 3.0 co-simulation FMUs of every model, from the same sources as the FMI 2.0 ones.

``ncfmu build`` writes each model's FMI 2.0 FMU to ``fmus/<Model>.fmu`` and its FMI 3.0 twin to
``fmus/fmi3/<Model>.fmu``. The twin is the same model behind another FMI layer: its binary is
``fmi/c/fmi3_functions.c`` over the model interface ``fmi/c/model.h``, compiled with the same model
(``python_model.c`` and the FMU's Python code in its resources, or ``native_model.c`` and the model's C file),
the same GUID (the FMI 3.0 ``instantiationToken``) and the same resources. Its modelDescription is written from
the model's ports by the FMI 2.0 one's writer (:mod:`.modeldesc`): a Real is a Float64, an Integer an Int32, with
units, ranges, start values and variabilities as the ports say them.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import BuildError
from .modeldesc import TIME_VR, model_description

if TYPE_CHECKING:
    from ..controllers.base import Controller

C_LAYER = Path(__file__).with_name("c")
FMI3_LAYER = C_LAYER / "fmi3_functions.c"
#: FMI 3.0's name of the platform the binary is built for (FMI 2.0's linux64).
PLATFORM = "x86_64-linux"


def _compile(sources: list[Path], includes: list[Path], defines: list[str], what: str) -> bytes:
    from .builder import SHIM_LINK, fmi_headers
    with tempfile.TemporaryDirectory(prefix="ncfmu_fmi3_") as tmp:
        out = Path(tmp) / "fmu.so"
        for cc in ("cc", "gcc", "clang"):
            if shutil.which(cc) is None:
                continue
            proc = subprocess.run([cc, "-shared", "-fPIC", "-O2", "-std=gnu11", "-Wall", *defines,
                                   f"-DNCFMU_TIME_VR={TIME_VR}u",          # the independent variable, one home
                                   f"-I{fmi_headers()}", *(f"-I{d}" for d in includes), "-o", str(out),
                                   *map(str, sources), *SHIM_LINK], capture_output=True, text=True)
            if proc.returncode != 0:
                raise BuildError(f"{what}: compiling the FMI 3.0 binary with {cc} failed: {proc.stderr.strip()[:500]}")
            return out.read_bytes()
    raise BuildError(f"{what}: no C compiler (cc, gcc or clang) found for the FMI 3.0 binary")


def build_fmi3(fmu2: Path, logic: type[Controller], dest_dir: Path) -> Path:
    """The FMI 3.0 twin of the FMI 2.0 FMU ``fmu2`` (same model, GUID, resources), written to ``dest_dir``."""
    from .builder import C_LAYER as LAYER
    from .builder import PYTHON_MODEL, _c_string
    name = logic.MODEL_NAME
    with zipfile.ZipFile(fmu2) as z:
        md2 = z.read("modelDescription.xml").decode()
        names = z.namelist()
        guid_match = re.search(r'\bguid="([^"]*)"', md2)
        version_match = re.search(r'\bversion="([^"]*)"', md2)
        if guid_match is None or version_match is None:
            raise BuildError(f"{fmu2}: no guid or version in its modelDescription")
        guid, version = guid_match.group(1), version_match.group(1)
        native = "sources/model_vars.h" in names
        with tempfile.TemporaryDirectory(prefix="ncfmu_fmi3_src_") as tmp:
            if native:
                src = Path(tmp)
                for item in names:
                    if item.startswith("sources/") and item.endswith((".c", ".h")):
                        (src / Path(item).name).write_bytes(z.read(item))
                model_c = next(src / Path(n).name for n in names if n.startswith("sources/") and n.endswith(".c")
                               and Path(n).name not in ("fmi2_functions.c", "native_model.c"))
                binary = _compile([FMI3_LAYER, src / "native_model.c", model_c], [src], [], name)
                sources: tuple[str, ...] | None = ("native_model.c", model_c.name)
            else:
                module = next((Path(n).stem for n in names
                               if re.fullmatch(rf"resources/{re.escape(name)}_[0-9a-f]{{12}}\.py", n)), None)
                if module is None:
                    raise BuildError(f"{fmu2}: no model module resources/{name}_<digest>.py")
                sources = None
                binary = _compile([FMI3_LAYER, PYTHON_MODEL], [LAYER],
                                  [f"-DNCFMU_GUID={_c_string(guid)}", f"-DNCFMU_MODULE={_c_string(module)}",
                                   f"-DNCFMU_CLASS={_c_string(name)}"], name)
        dest_dir = Path(dest_dir)
        dest_dir.mkdir(parents=True, exist_ok=True)
        target = dest_dir / f"{name}.fmu"
        partial = target.with_suffix(".fmu.part")
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as out:
            out.writestr("modelDescription.xml", model_description(logic, "3.0", guid, version,
                                                                   native_sources=sources))
            out.writestr(f"binaries/{PLATFORM}/{name}.so", binary)
            for info in z.infolist():
                if info.filename.startswith(("resources/", "documentation/")) and not info.is_dir():
                    out.writestr(info.filename, z.read(info.filename))
    partial.replace(target)
    return target


def _identity(fmu: Path, token: str) -> tuple[str | None, str | None, list[str]]:
    """(version, GUID or instantiationToken, files) of an FMU; Nones when it cannot be read."""
    try:
        with zipfile.ZipFile(fmu) as z:
            text, names = z.read("modelDescription.xml").decode(), z.namelist()
    except (OSError, KeyError, zipfile.BadZipFile):
        return None, None, []
    version, guid = re.search(r'\bversion="([^"]*)"', text), re.search(rf'\b{token}="([^"]*)"', text)
    return (version.group(1) if version else None), (guid.group(1) if guid else None), names


def _twin_of(fmu3: Path, fmu2: Path, model: str) -> bool:
    """``fmu3`` was built from ``fmu2`` as it is now: the same version and GUID (a rebuilt FMI 2.0 FMU has a
    new GUID even from the same sources), and it has its binary."""
    version3, token, names = _identity(fmu3, "instantiationToken")
    version2, guid, _ = _identity(fmu2, "guid")
    return (version3 is not None and guid is not None and (version3, token) == (version2, guid)
            and f"binaries/{PLATFORM}/{model}.so" in names)


def build_all_fmi3(fmus: list[Path], dest_dir: Path, only_stale: bool = False) -> list[Path]:
    """The FMI 3.0 twin of every FMI 2.0 FMU in ``fmus`` (named by its model), in ``dest_dir``; with
    ``only_stale``, one built from the same sources is kept."""
    from ..catalogue import models
    built = []
    for fmu2 in fmus:
        logic = models()[Path(fmu2).stem]
        target = Path(dest_dir) / f"{logic.MODEL_NAME}.fmu"
        if only_stale and target.exists() and _twin_of(target, Path(fmu2), logic.MODEL_NAME):
            built.append(target)
            continue
        built.append(build_fmi3(Path(fmu2), logic, dest_dir))
    return built
