"""Refactors keep behaviour: every system's default run, bit for bit, against digests stored in the repo.

Each system's columns as of the digest file (new outputs added later do not count); a digest is the SHA-256 of
the column's float64/int32/bool bytes. A change of behaviour that is meant (a fix, a new default) regenerates
the file with ``python tests/systems/test_trajectory_digests.py`` and says so in its commit.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import pytest

from ncfmu.systems import SYSTEMS

DIGESTS = Path(__file__).with_name("trajectory_digests.json")


def digests(result, columns=None) -> dict[str, str]:
    names = columns if columns is not None else ["time", *result.names]
    return {n: hashlib.sha256(result.data[n].tobytes()).hexdigest() for n in names}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_default_run_is_bit_identical(name, ncfmu_run):
    stored = json.loads(DIGESTS.read_text())
    assert name in stored, f"{name}: no stored digests; regenerate {DIGESTS.name}"
    result = ncfmu_run(name)
    now = digests(result, list(stored[name]))
    changed = [n for n in stored[name] if now[n] != stored[name][n]]
    assert not changed, f"{name}: {len(changed)} columns differ from the stored run, e.g. {changed[:5]}"


if __name__ == "__main__":        # regenerate: python tests/systems/test_trajectory_digests.py
    from ncfmu.project import simulate
    out = {name: digests(simulate(name)) for name in sorted(SYSTEMS)}
    DIGESTS.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
    print(f"{DIGESTS}: {sum(len(v) for v in out.values())} columns of {len(out)} systems", file=sys.stderr)
