"""ecos (pip ``ecospy``) on a machine that has only Python: where its TBB runtime comes from.

ecospy's library and its ``ecos`` command-line program link ``libtbb.so.12`` and look for it on the
system's library path only (Debian's ``libtbb12``). The PyPI wheel ``tbb`` (a test extra) installs the
same library into ``<environment>/lib``; these helpers point ecos at it, so nothing is installed outside the
Python environment. Only the test suite and the benchmarks use ecos; ncfmu itself never does.
"""

from __future__ import annotations

import ctypes
import importlib.util
import os
import shutil
import sys
from pathlib import Path
from types import ModuleType

TBB = "libtbb.so.12"


def tbb_directory() -> Path | None:
    """The folder where pip's ``tbb`` wheel put ``libtbb.so.12`` (``sys.prefix/lib``), if it did."""
    folder = Path(sys.prefix) / "lib"
    return folder if (folder / TBB).is_file() else None


def environment(base: dict[str, str] | None = None) -> dict[str, str]:
    """``base`` (default: this process's environment) with the TBB folder first on ``LD_LIBRARY_PATH``: the
    environment to start the ``ecos`` program in."""
    env = dict(os.environ if base is None else base)
    folder = tbb_directory()
    if folder is not None:
        env["LD_LIBRARY_PATH"] = os.pathsep.join(p for p in (str(folder), env.get("LD_LIBRARY_PATH", "")) if p)
    return env


def import_ecospy() -> ModuleType:
    """``import ecospy`` with its TBB runtime loaded first (from pip's ``tbb`` wheel when it is there)."""
    folder = tbb_directory()
    if folder is not None:
        ctypes.CDLL(str(folder / TBB), mode=ctypes.RTLD_GLOBAL)   # ecospy's CDLL then finds it loaded
    import ecospy
    return ecospy


def ecos_program(destination: Path) -> Path:
    """A runnable copy of the ``ecos`` program ecospy ships (the wheel ships it without the execute bit;
    site-packages is left alone). Found without importing ecospy."""
    spec = importlib.util.find_spec("ecospy")
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError("ecospy is not installed (a test extra: pip install -e '.[test]')")
    shipped = Path(list(spec.submodule_search_locations)[0]) / "binaries" / "ecos"
    if not shipped.is_file():
        raise FileNotFoundError(f"ecospy ships no ecos program at {shipped}")
    destination = Path(destination)
    destination.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(shipped, destination)
    destination.chmod(0o755)
    return destination
