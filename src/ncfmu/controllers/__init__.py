"""Controller logic as plain Python classes (no pythonfmu, no fmpy)."""

from .base import Controller
from .panel import OperatorPanel
from .limiter import AreaLimiter
from .sequencer import Block, CutSequencer

__all__ = ["Controller", "AreaLimiter", "OperatorPanel", "CutSequencer", "Block"]
