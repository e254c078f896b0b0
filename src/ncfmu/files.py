"""Writing files: atomically, and generated files only when their content changes.

A run builds what is missing and nothing else, so it must not touch a file whose content is already right
(``ncfmu run`` changes no file of the checkout, not even a timestamp).
"""

from __future__ import annotations

import os
from pathlib import Path


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename: a reader sees the old or the new file."""
    path = Path(path)
    part = path.with_name(path.name + ".part")
    with open(part, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    part.replace(path)


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
