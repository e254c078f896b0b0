"""Serialized FMU states refuse corruption and other FMI versions (issue 45).

Every serialized state is sealed by the FMI layer (``fmi/c/fmu_instance.h``; the format in
:mod:`ncfmu.fmi.sealed_state`): a format version, the FMI version and the model that made it, and a CRC-32 of it
all. 400 seeded single-bit flips of a real state of each model, FMI 2.0 and 3.0, are refused (CRC-32 detects every
single-bit error), and a state of the FMI 2.0 build is refused by the FMI 3.0 build and back, naming why.

Each model's flips run in one process of its own (tests/fmi/state_flips_host.py): a crash is a failure, not a
lost test run.
"""

from __future__ import annotations

import json
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

from ncfmu.fmi.sealed_state import Sealed, SealError, crc32, seal, unseal

HOST = Path(__file__).with_name("state_flips_host.py")
FLIPS, SEED = 400, 45
#: at most this share of the flips may be accepted, and none may change an output after a step
ACCEPTED_AT_MOST = 0.01

_RUNS: dict[str, tuple[dict, str]] = {}


def flipped(project, model: str) -> tuple[dict, str]:
    """The host's result for ``model`` (run once per test session) and what it printed."""
    if model not in _RUNS:
        fmi2 = next(p for p in project["fmus"] if p.stem == model)
        fmi3 = next(p for p in project["fmi3"] if p.stem == model)
        proc = subprocess.run([sys.executable, str(HOST), str(fmi2), str(fmi3), str(FLIPS), str(SEED)],
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, (proc.returncode, proc.stdout[-2000:], proc.stderr[-3000:])   # no crash
        line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")][-1]
        _RUNS[model] = json.loads(line.split(" ", 1)[1]), proc.stdout
    return _RUNS[model]


@pytest.mark.parametrize("model", ["ServoAxis", "SpindleDrive", "AreaLimiter"])
@pytest.mark.parametrize("fmi", ["2.0", "3.0"])
def test_single_bit_flips_of_a_state_are_refused(project, model, fmi):
    result, log = flipped(project, model)
    flips = result[fmi]
    assert flips["flips"] == FLIPS and flips["size"] > 100
    assert flips["accepted"] <= ACCEPTED_AT_MOST * FLIPS, flips
    assert flips["n_changed"] == 0, flips
    call = "fmi2DeSerializeFMUstate" if fmi == "2.0" else "fmi3DeserializeFMUState"
    assert f"{call}: {flips['size']} bytes refused: checksum" in log


@pytest.mark.parametrize("model", ["ServoAxis", "SpindleDrive", "AreaLimiter"])
def test_a_state_of_the_other_fmi_version_is_refused_naming_it(project, model):
    result, log = flipped(project, model)
    assert result["2.0->3.0"] == result["3.0->2.0"] == "Error", result
    said = log.split("CROSS 2.0 -> 3.0", 1)[1]
    to3, to2 = said.split("CROSS 3.0 -> 2.0", 1)
    assert f"a state of the FMI 2.0 build of {model}; this is its FMI 3.0 build" in to3, to3[-2000:]
    assert f"a state of the FMI 3.0 build of {model}; this is its FMI 2.0 build" in to2, to2[-2000:]


@pytest.mark.parametrize("model", ["ServoAxis", "SpindleDrive", "AreaLimiter"])
def test_the_seal_reads_alike_in_c_and_python(project, model):
    """A state the C layer sealed unseals here: zlib's CRC-32 of its bytes is the one the C layer stored, and the
    seal names the model and the FMI version that made it."""
    _, log = flipped(project, model)
    good = {ln.split()[1]: bytes.fromhex(ln.split()[2]) for ln in log.splitlines() if ln.startswith("GOOD ")}
    assert set(good) == {"2.0", "3.0"}
    for fmi, blob in good.items():
        sealed = unseal(blob)
        assert (sealed.model, sealed.fmi) == (model, int(fmi[0]))
        assert int.from_bytes(blob[-4:], "little") == zlib.crc32(blob[:-4])
        assert seal(sealed.payload, model, int(fmi[0])) == blob
    assert unseal(good["2.0"]).payload == unseal(good["3.0"]).payload     # the same model state, sealed apart


def test_the_seal_refuses_what_is_not_a_sealed_state():
    blob = seal(b"payload", "ServoAxis", 3)
    assert crc32(b"123456789") == 0xCBF43926                           # the CRC-32 check value (IEEE 802.3)
    assert unseal(blob) == Sealed(b"payload", "ServoAxis", 3)
    for bad, says in ((blob[:-1], "holds 7 bytes of state, the bytes given 6"), (b"x" * 10, "too short"),
                      (b"X" + blob[1:], "no 'ncfmu-st' seal"), (blob[:8] + b"\2" + blob[9:], "seal format version 2"),
                      (blob[:-5] + b"P" + blob[-4:], "checksum mismatch")):
        with pytest.raises(SealError, match=says):
            unseal(bad)
