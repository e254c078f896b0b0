"""Twin runs for the refused-value properties: two instances of one model stepped side by side, one of them
offered values (in plain Python or through the FMU), the other never shown the ones that were refused.

What both use: the inputs of a small closed loop that makes every model do something (an ideal servo that
follows each position command, a start push, an M word answered), and the values offered to a variable, each
drawn from its type with the edges of its rule and the values a careless host sends (NaN, infinities, the
smallest subnormal, the type's extremes).
"""

from __future__ import annotations

import math

from hypothesis import strategies as st

#: Reals every rule has to face: NaN, the infinities, both zeros, the smallest subnormal, the largest finite.
REAL_EDGES = (math.nan, math.inf, -math.inf, 0.0, -0.0, 5e-324, -5e-324, 1e-9, -1.0, 1.0, 1e308, -1e308)
INT_EDGES = (0, 1, -1, 2**31 - 1, -(2**31))


def offered_values(fmi_type: str, start: object, lo: float | None, hi: float | None,
                   related: tuple[float, ...] = ()) -> st.SearchStrategy:
    """Values a host may set into a variable of ``fmi_type`` with the range ``lo``..``hi`` (None: unbounded).
    ``related``: the values of the model's other parameters -- a rule that ties parameters together (a period
    longer than a pulse) breaks at them, their halves and their neighbours, so those are offered often."""
    if fmi_type == "Real":
        edges = [*REAL_EDGES, start]
        for bound in (lo, hi):
            if bound is not None:
                edges += [bound, math.nextafter(bound, -math.inf), math.nextafter(bound, math.inf)]
        near = [y for x in related if math.isfinite(x)
                for y in (x, x / 2, math.nextafter(x, -math.inf), math.nextafter(x, math.inf))]
        return st.one_of(st.sampled_from(edges), st.sampled_from(near or edges), st.floats(), st.floats(-1e3, 1e3),
                         st.floats(-0.1, 0.1))
    if fmi_type == "Integer":
        edges = [*INT_EDGES, start]
        for bound in (lo, hi):
            if bound is not None:
                edges += [int(bound) - 1, int(bound), int(bound) + 1]
        near = [y for x in related if math.isfinite(x) and abs(x) < 2**31 - 1 for y in (int(x), int(x) + 1)]
        return st.one_of(st.sampled_from([e for e in edges if -(2**31) <= e < 2**31]), st.sampled_from(near or edges),
                         st.integers(-(2**31), 2**31 - 1), st.integers(-5, 50))
    if fmi_type == "Boolean":
        return st.booleans()
    # text a host can pass as UTF-8 (no surrogates, no NUL: C strings end there)
    return st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=40)


#: Parameters that make a model busy within the first steps of the loop (else its defaults): the panel pushes its
#: buttons, holds the feed and answers an M word early.
LOOP_PARAMETERS: dict[str, dict[str, object]] = {
    "OperatorPanel": {"start_at": 0.0, "wear_start_at": 0.005, "emergency_at": 0.03, "hold_at": 0.01,
                      "release_at": 0.02, "mfin_delay": 0.02},
}


def loop_inputs(model: str, k: int, inputs: dict, outputs: dict) -> dict:
    """The inputs of step ``k`` of ``model`` in a small closed loop, from the outputs of the step before
    (updated in place and returned): every ``<a>_pos`` follows its ``<a>_cmd`` (an ideal servo, always in
    position), START is pushed for the first steps, an M word is answered, the limiter and the drives follow a ramp."""
    for name in list(inputs):
        if name.endswith("_pos") and name[:-4] + "_cmd" in outputs:
            inputs[name] = outputs[name[:-4] + "_cmd"]
    if "start" in inputs:
        inputs["start"] = 1 <= k <= 3
    if "mfin" in inputs:
        inputs["mfin"] = bool(outputs.get("m_active"))
    if model == "OperatorPanel":
        inputs["m_active"] = 3 if k >= 10 else 0
    elif model == "AreaLimiter":
        for axis in ("ref", "lim"):
            inputs[f"{axis}_cmd_in"] = 0.05 * k
            inputs[f"{axis}_vff_in"] = 50.0
            inputs[f"{axis}_pos"] = outputs.get(f"{axis}_cmd", 0.0)
    elif model == "ServoAxis":
        inputs["pos_cmd"] = 0.01 * k
        inputs["vel_ff"] = 10.0
    elif model == "SpindleDrive":
        inputs["speed_cmd"] = 20.0 * k
    return inputs


def same_bits(a: object, b: object) -> bool:
    """Equal to the bit (a float's sign of zero and NaN included), recursively through dicts and sequences."""
    if isinstance(a, float) and isinstance(b, float):
        return math.copysign(1.0, a) == math.copysign(1.0, b) and (a == b or (math.isnan(a) and math.isnan(b)))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same_bits(a[key], b[key]) for key in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(same_bits(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b
