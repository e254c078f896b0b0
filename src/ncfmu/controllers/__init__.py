"""Controller logic as plain Python classes (no pythonfmu, no fmpy)."""

from .base import Controller
from .contour import ContourInterpolator
from .feed import ProgrammableFeed, parse_program
from .limiter import AreaLimiter
from .panel import OperatorPanel
from .sequencer import Block, CutSequencer

__all__ = ["Controller", "ContourInterpolator", "AreaLimiter", "ProgrammableFeed", "parse_program",
           "OperatorPanel", "CutSequencer", "Block"]
