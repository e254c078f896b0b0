"""The seal around every serialized ncfmu FMU state, as the FMI layer writes and checks it (``fmi/c/fmu_instance.h``).

An FMU's ``fmi2SerializeFMUstate`` / ``fmi3SerializeFMUState`` bytes are the model's own bytes (a native model's
plain data, a Python model's JSON from :mod:`ncfmu.fmi.state` with the shim's trailer) sealed::

    b"ncfmu-st" | u32 seal format version | u32 FMI major version (2, 3) | model identifier [64], NUL-padded |
    u64 size of the model's bytes | the model's bytes | u32 CRC-32 of every byte before it

integers little-endian, the CRC-32 zlib's (IEEE 802.3). The FMU refuses a state whose seal format version,
checksum, model or FMI version is not its own, naming which. This module reads and writes the same format for
tools and tests (a state edited on purpose is sealed again here); the C layer never calls it.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

from ..errors import NcfmuError

MAGIC = b"ncfmu-st"
#: The seal's format version (FMU_SEAL_VERSION in fmu_instance.h).
VERSION = 1
MODEL_SIZE = 64
_HEADER = struct.Struct(f"<8sII{MODEL_SIZE}sQ")
_CRC = struct.Struct("<I")
#: What the seal adds to the model's bytes.
OVERHEAD = _HEADER.size + _CRC.size


class SealError(NcfmuError, ValueError):
    """Bytes that are not a sealed ncfmu FMU state, or whose seal does not hold (names which part)."""


@dataclass(frozen=True)
class Sealed:
    """A sealed state's parts."""

    payload: bytes              # the model's bytes
    model: str                  # the model identifier that made it
    fmi: int                    # the FMI major version of the build that made it (2 or 3)


def crc32(data: bytes) -> int:
    """The CRC-32 the seal carries (zlib's)."""
    return zlib.crc32(data) & 0xFFFFFFFF


def seal(payload: bytes, model: str, fmi: int) -> bytes:
    """``payload`` sealed as the FMI ``fmi`` build of ``model`` seals it."""
    name = model.encode("ascii")
    if not name or len(name) >= MODEL_SIZE or fmi not in (2, 3):
        raise SealError(f"cannot seal a state of model {model!r}, FMI {fmi}")
    head = _HEADER.pack(MAGIC, VERSION, fmi, name, len(payload)) + bytes(payload)
    return head + _CRC.pack(crc32(head))


def unseal(data: bytes) -> Sealed:
    """The parts of a sealed state; SealError when it is not one (too short, no magic, another seal format
    version, a size that does not match, a checksum that does not match)."""
    data = bytes(data)
    if len(data) < OVERHEAD:
        raise SealError(f"{len(data)} bytes: too short to be a sealed FMU state ({OVERHEAD} at least)")
    magic, version, fmi, name, size = _HEADER.unpack_from(data)
    if magic != MAGIC:
        raise SealError(f"not an ncfmu FMU state (no {MAGIC.decode()!r} seal)")
    if version != VERSION:
        raise SealError(f"seal format version {version}; this reads version {VERSION}")
    if size != len(data) - OVERHEAD:
        raise SealError(f"its seal holds {size} bytes of state, the bytes given {len(data) - OVERHEAD}")
    (stored,) = _CRC.unpack_from(data, len(data) - _CRC.size)
    computed = crc32(data[:-_CRC.size])
    if stored != computed:
        raise SealError(f"checksum mismatch (CRC-32 {stored:08x} stored, {computed:08x} computed)")
    return Sealed(data[_HEADER.size:-_CRC.size], name.rstrip(b"\0").decode("ascii", "replace"), fmi)
