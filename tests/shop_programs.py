"""Shop programs more than one test runs (the Fanuc 0i-T dialect, README's table)."""

#: G94 facing and G90 turning passes under G54: the bar's end faced 2 mm deep down to X40 (two G94 passes, text
#: lines 6 and 7), then turned to X50 over 15 mm in two G90 passes (lines 9 and 10), the last a taper (R-1: the cut
#: starts 1 mm, radius, below its end's X: X48 at Z2 rising to X50 at Z-15). Judged by the passes' own definition.
PASSES = """G21 G40 G98
G54
T0101
G97 S800 M03
G00 X64. Z2.
G94 X40. Z-1. F600
Z-2.
G00 X60. Z2.
G90 X54. Z-15. F600
X50. R-1.
G00 X64. Z5.
M05
M30
"""
