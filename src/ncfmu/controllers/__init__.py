"""Controller logic as plain Python classes (no pythonfmu, no fmpy)."""

from .base import Controller
from .panel import OperatorPanel
from .sequencer import Block, CutSequencer

__all__ = ["Controller", "OperatorPanel", "CutSequencer", "Block"]
