"""The exit statuses of ``ncfmu run`` and ``ncfmu sweep``: one home, so a CI job can gate on them.

- ``EXIT_OK`` 0: the work is done and judged good (for a system without a part check: done; for one without a
  done signal, a bare FMU: it ran to its stop time).
- ``EXIT_PROBLEMS`` 1: ``ncfmu validate`` found problems, ``ncfmu serve`` failed.
- ``EXIT_REFUSED`` 2: the command was refused (a bad option or value, a system that does not read).
- ``EXIT_PART_REJECTED`` 3: the part check saw a crash, or the part is out of tolerance.
- ``EXIT_NOT_FINISHED`` 4: the work did not finish: the stop-time limit was reached, an alarm halted the
  machine, or the part could not be judged.
"""

from __future__ import annotations

EXIT_OK = 0
EXIT_PROBLEMS = 1
EXIT_REFUSED = 2
EXIT_PART_REJECTED = 3
EXIT_NOT_FINISHED = 4

#: ``--help``'s and the README's words for them (ncfmu run and ncfmu sweep)
EXIT_HELP = (f"Exit status: {EXIT_OK} done and judged good; {EXIT_PART_REJECTED} a crash or a part out of "
             f"tolerance; {EXIT_NOT_FINISHED} not finished (the --stop-time limit reached, an alarm, the part not "
             f"judged); {EXIT_REFUSED} refused (a bad command line or system).")
