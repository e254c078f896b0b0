"""A part drawn for the part check's ``--drawing``: a closed outline of (Z, radius) points as DXF lines, in mm."""

from __future__ import annotations

from pathlib import Path

import ezdxf


def outline_dxf(path: Path, outline: list[tuple[float, float]]) -> Path:
    """``outline`` closed (the last point back to the first) as LINE entities of a drawing in mm, saved at ``path``."""
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    for a, b in zip(outline, outline[1:] + outline[:1]):
        msp.add_line(a, b)
    doc.saveas(path)
    return path
