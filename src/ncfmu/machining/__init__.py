"""Material removal from the servo axes' actual positions: stock, tool, fixtures, crashes and the part made.

The engine (:mod:`.removal`) is plane geometry on shapely (GEOS) polygons, fed the tool's positions chunk by
chunk as a run goes; it keeps the stock left and the crashes seen, never the trajectory. It knows nothing of
systems or controllers' ports: :mod:`ncfmu.systems.part` builds its stock, tool, fixtures and the programmed
part from a run's parameters and reads the recorded signals.
"""

from .removal import (
                      Crash,
                      Cutter,
                      Deviation,
                      MaterialRemoval,
                      Move,
                      deviation,
                      drill,
                      grooving_insert,
                      lathe_tool,
                      mill_cutter,
                      placed,
                      turning_insert,
)

__all__ = ["Crash", "Cutter", "Deviation", "MaterialRemoval", "Move", "deviation", "drill", "grooving_insert",
           "lathe_tool", "mill_cutter", "placed", "turning_insert"]
