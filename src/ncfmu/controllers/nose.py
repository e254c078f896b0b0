"""A lathe's tool-nose radius compensation (G40/G41/G42), in the (z, x) plane of :mod:`.lathe_program`.

The insert's nose is a circle of radius r; the program describes the part. Under G41 (the nose left of the
direction of travel, seen from +Y with Z to the right and X up, as on a lathe drawing) or G42 (right) the
nose centre runs on the profile offset by r to that side (:func:`.geometry.compensate`, the mill's offset,
with an arc of radius r around every outside corner -- the nose circle touches the corner all the way round --
and the offsets trimmed to their intersection at inside corners). The axes command the **imaginary tool tip**,
the point the tool was set to (the tool offsets measure it): nose centre + the tip vector of Fanuc's imaginary
tool-nose number (the tool table's ``tip``), each component +-r or 0:

==== =========== ==========  ==============================================================
tip  Z (right)   X (up)      the tool
==== =========== ==========  ==============================================================
0, 9   0           0         the nose centre is programmed
1     +r          +r
2     -r          +r         boring bar cutting toward the chuck (ID)
3     -r          -r         turning tool cutting toward the chuck (OD)
4     +r          -r
5     +r           0
6      0          +r
7     -r           0
8      0          -r
==== =========== ==========  ==============================================================

(Fanuc 0i-T's figure for a lathe whose +X points up: 1..4 the corners, 5..8 the sides, each set counter-clockwise
from +Z.) With compensation off the programmed point is the imaginary tip.

Start-up and cancel are Fanuc's type A, as the mill's (:func:`.contour.program_path`): the start-up block (the
first move after G41/G42) ends with the nose centre at the offset of the NEXT block's start point, normal to
that block; the cancel block (the move with G40, or the move to a canned cycle's start point) starts from the
offset of the PREVIOUS block's end point, normal to it, and ends at its programmed point uncompensated. Both
are straight moves.
"""

from __future__ import annotations

from dataclasses import dataclass

from .geometry import Arc, Element, Line, Point, compensate

#: Fanuc's imaginary tool-nose numbers: the tip's direction from the nose centre, (z, x) per unit radius.
TIP: dict[int, Point] = {0: (0.0, 0.0), 1: (1.0, 1.0), 2: (-1.0, 1.0), 3: (-1.0, -1.0), 4: (1.0, -1.0),
                         5: (1.0, 0.0), 6: (0.0, 1.0), 7: (-1.0, 0.0), 8: (0.0, -1.0), 9: (0.0, 0.0)}


def translated(e: Element, dz: float, dx: float) -> Element:
    """The element moved by (dz, dx)."""
    if isinstance(e, Line):
        return Line((e.start[0] + dz, e.start[1] + dx), (e.end[0] + dz, e.end[1] + dx))
    return Arc((e.center[0] + dz, e.center[1] + dx), e.radius, e.a0, e.sweep)


@dataclass(frozen=True)
class Nose:
    """G41 (``side`` +1) or G42 (-1) with a tool of nose radius ``radius`` and imaginary tip ``tip``."""

    side: int
    radius: float
    tip: int

    @property
    def code(self) -> str:
        return "G41" if self.side > 0 else "G42"

    @property
    def vector(self) -> Point:
        """The imaginary tip from the nose centre (z, x)."""
        uz, ux = TIP[self.tip]
        return (uz * self.radius, ux * self.radius)

    def tip_of(self, centre: Point) -> Point:
        vz, vx = self.vector
        return (centre[0] + vz, centre[1] + vx)

    def path(self, chain: list[Element]) -> list[tuple[Element, int]]:
        """The commanded pieces (imaginary tip) of ``chain`` compensated: (piece, index of its element).

        Raises
        ------
        .geometry.CornerError
            an arc smaller than the nose on its concave side, an inside corner the nose cannot reach, an offset
            that comes closer than r to the profile elsewhere (the nose would gouge).
        """
        pieces = compensate(chain, self.side * self.radius, closed=False, round_corners=True)
        vz, vx = self.vector
        if (vz, vx) == (0.0, 0.0):
            return pieces
        return [(translated(e, vz, vx), k) for e, k in pieces]
