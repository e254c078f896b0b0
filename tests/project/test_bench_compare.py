"""bench/compare.py refuses what is not a commit before it checks anything out (one line, exit 2)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_compare_refuses_a_revision_that_is_no_commit(tmp_path):
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "compare.py"), "no-such-rev-xyz", "HEAD",
                          "--work", str(tmp_path)], capture_output=True, text=True)
    assert out.returncode == 2
    assert "not a commit: 'no-such-rev-xyz'" in out.stderr
    assert not any(tmp_path.iterdir())      # nothing checked out or installed


def test_compare_refuses_a_non_positive_stop_time(tmp_path):
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "compare.py"), "HEAD", "HEAD", "--stop-time", "0",
                          "--work", str(tmp_path)], capture_output=True, text=True)
    assert out.returncode == 2
    assert "--stop-time" in out.stderr
