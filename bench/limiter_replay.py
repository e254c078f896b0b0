"""Limiter step cost for callgrind: N steps of precomputed inputs (straight moves inside the grinder table,
use_actual, passing throughout).

    PYTHONHASHSEED=0 valgrind --tool=callgrind python bench/limiter_replay.py N PREDICTIVE

Count a run of N=3000 and one of N=0 (the set-up alone) and divide the difference by 3000.
"""

import sys

from ncfmu.controllers.limiter import AreaLimiter
from ncfmu.controllers.motion import LinearMove

GRINDER = [(200.0, -1e6, 250.0), (350.0, -1e6, 80.0), (800.0, -1e6, 180.0), (1000.0, -1e6, 60.0)]
DT = 1e-3
MOVES = [((100.0, 0.0), (100.0, 200.0), 150.0), ((100.0, 200.0), (150.0, 20.0), 80.0),
         ((150.0, 20.0), (700.0, 50.0), 200.0), ((700.0, 50.0), (700.0, 170.0), 30.0),
         ((700.0, 170.0), (300.0, 30.0), 120.0)]


def main() -> None:
    n, predictive = int(sys.argv[1]), sys.argv[2] == "1"
    inputs = []
    move = LinearMove(500.0)
    for a, b, v in MOVES:
        move.begin(a, b, v)
        while not move.done:
            move.advance(DT, 1.0)
            (r, x), (vr, vx) = move.position(), move.velocity()
            inputs.append({"ref_cmd_in": r, "lim_cmd_in": x, "ref_vff_in": vr, "lim_vff_in": vx,
                           "ref_pos": r, "lim_pos": x})
    inputs = (inputs * (1 + 3000 // len(inputs)))[:3000]
    lim = AreaLimiter.with_table(GRINDER, ref_start=100.0, lim_start=0.0, predictive=predictive, use_actual=True)
    step, t = lim.step, 0.0
    for k in range(n):
        step(t, DT, inputs[k])
        t += DT
    print(n, lim.outputs()["ref_cmd"], lim.outputs()["lim_cmd"], lim.alarm)


if __name__ == "__main__":
    main()
