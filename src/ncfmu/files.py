"""Where the project's files are, and writing them: atomically, and generated files only when their content changes.

A run builds what is missing and nothing else, so it must not touch a file whose content is already right
(``ncfmu run`` changes no file of the checkout, not even a timestamp).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import socket
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from .version import __version__


@functools.cache
def machine_id() -> str:
    """8 hex digits naming this machine and its process-id namespace (a container has its own): a pid names a
    process only there -- on another host sharing a folder (NFS) or in another container, it is another's, or
    none."""
    try:
        namespace = str(os.stat("/proc/self/ns/pid").st_ino)
    except OSError:
        namespace = ""
    return hashlib.sha256(f"{socket.gethostname()}/{namespace}".encode()).hexdigest()[:8]


def writer_id() -> str:
    """``<pid>@<machine>``: which process writes a temporary file, in its name (``NAME.<writer_id>.part``, a
    sweep's ``<key>-<writer_id>.rows``), so that another process tells a leftover from a file being written."""
    return f"{os.getpid()}@{machine_id()}"


@contextlib.contextmanager
def atomic_file(path: Path) -> Iterator[BinaryIO]:
    """A file to write ``path``'s bytes into, renamed to ``path`` once they are on disk (a reader sees the old or
    the new file). The temporary file is ``NAME.<pid>@<machine>.part`` (:func:`writer_id`): two processes writing
    one file never write into one temporary file, and a leftover says whose it was; an error removes it."""
    path = Path(path)
    part = path.with_name(f"{path.name}.{writer_id()}.part")
    try:
        with open(part, "wb") as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        part.replace(path)
    except BaseException:
        with contextlib.suppress(OSError):      # the error to tell is the write's
            part.unlink(missing_ok=True)        # named by this process: no later write would ever replace it
        raise


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through :func:`atomic_file`."""
    with atomic_file(path) as f:
        f.write(data)


def write_if_changed(path: Path, data: bytes) -> bool:
    """Write ``data`` (atomically) unless ``path`` holds exactly it already; return whether it was written."""
    path = Path(path)
    try:
        if path.read_bytes() == data:
            return False
    except FileNotFoundError:
        pass
    write_atomic(path, data)
    return True


def is_checkout(folder: Path) -> bool:
    return (folder / "models" / "CutSequencer.py").is_file() and (folder / "pyproject.toml").is_file()


def project_root() -> Path:
    """Where models are read and FMUs, systems (and, in a checkout, docs) are written.

    ``$NCFMU_ROOT`` when set; else the ncfmu checkout holding the working directory; else the checkout an
    editable install points at; else (an installed wheel, anywhere) a per-version user cache,
    ``$NCFMU_CACHE`` or ``$XDG_CACHE_HOME/ncfmu/<version>`` (``~/.cache/ncfmu/<version>``).
    """
    env = os.environ.get("NCFMU_ROOT")
    if env:
        return Path(env)
    cwd = Path.cwd().resolve()
    for folder in (cwd, *cwd.parents, Path(__file__).resolve().parents[2]):
        if is_checkout(folder):
            return folder
    cache = os.environ.get("NCFMU_CACHE")
    if cache:
        return Path(cache)
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "ncfmu" / __version__
