"""Which settings a system can feel: a ``--set`` whose effect reaches no connected port deserves a warning.

The rule, for each ``INSTANCE.VARIABLE`` set (a parameter or an input of a model ncfmu defines; the
instances of other models are not judged):

- The variable acts on the outputs its model's ``ACTS_ON`` names for it, else on every output of its
  instance. The OperatorPanel names them: ``start_at`` and ``restart_at`` act on ``start``,
  ``wear_start_at`` on ``wear_start``, ``emergency_at`` on ``emergency``, ``hold_at`` and ``release_at`` on
  ``feed_hold``, ``override`` on ``feed_override``, ``mfin_delay`` (and the input ``m_active``) on ``mfin``,
  ``pulse`` on the three push buttons. When no connection starts at any of those outputs, the setting
  reaches nothing (``panel.emergency_at`` in a lathe system, whose sequencer has no EMB input). A system of one
  instance (a bare FMU run alone) records what its outputs say: they are the result, each one read.
- A parameter its model's ``unread`` names for the run's parameter set (the system's, with the run's
  settings on top) reaches nothing: an entry ``<head>[k].<field>`` of a counted table beyond its count
  ``n_<head>s`` (the CutSequencer's ``block[k]``, the AreaLimiter's ``region[k]``, the ContourInterpolator's
  ``point[k]``); the ContourInterpolator's point path (``point[k]``, ``n_points``, ``closed``, ``side``,
  ``feed``) when ``program`` is set; a ProgrammableFeed's D, F or T setting its program names nowhere.
"""

from __future__ import annotations

from collections.abc import Mapping

from ..cosim.ssp import System
from .compose import MODELS


def unreached(system: System, values: Mapping[str, object]) -> dict[str, str]:
    """``INSTANCE.VARIABLE -> why it reaches nothing`` for each of ``values`` (the settings of one run) that
    reaches no connected port of ``system``; names the system does not have are left to the master."""
    out: dict[str, str] = {}
    read = {(c.start_element, c.start_connector) for c in system.connections}
    instances = {c.name: c for c in system.components}
    for qualified in values:
        inst, _, var = qualified.partition(".")
        comp = instances.get(inst)
        logic = MODELS.get(comp.model) if comp is not None else None
        if comp is None or logic is None:
            continue
        ports = {p.name: p for p in logic.PORTS}
        if var not in ports or ports[var].causality == "output":
            continue
        if ports[var].causality == "parameter":
            mine = {name.partition(".")[2]: v for name, v in values.items() if name.partition(".")[0] == inst}
            why = logic.unread({**logic.default_parameters(), **comp.parameters, **mine}).get(var)
            if why:
                out[qualified] = f"{inst} {why}: {qualified} changes nothing"
                continue
        if len(instances) == 1:
            continue            # a bare FMU run alone: its outputs are the run's result, so each one is read
        outputs = logic.ACTS_ON.get(var, tuple(p.name for p in logic.ports("output")))
        if not any((inst, o) in read for o in outputs):
            acts = ", ".join(f"{inst}.{o}" for o in outputs)
            out[qualified] = (f"{qualified} acts only on {acts}, which no connection of {system.name} reads: "
                              "it changes nothing in this system" if logic.ACTS_ON.get(var) else
                              f"no connection of {system.name} reads an output of {inst}: {qualified} changes "
                              "nothing in this system")
    return out
