"""bench/compare.py refuses what is not a commit before it checks anything out (one line, exit 2)."""

from __future__ import annotations

import importlib.util
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


def _compare_module():
    spec = importlib.util.spec_from_file_location("ncfmu_bench_compare", ROOT / "bench" / "compare.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_one_revision_s_sides_are_named_by_how_each_is_built():
    """Two builds of one revision are two sides (an A/A run too: both once measured into one list, ratio 1.000
    whatever the noise), each named by how it is built -- ``--compiled a`` has A compiled, B pure."""
    labels = _compare_module().side_labels
    assert labels("HEAD", "HEAD~1", "b") == ("HEAD", "HEAD~1")
    assert labels("HEAD", "HEAD", "b") == ("HEAD (pure)", "HEAD (compiled)")
    assert labels("HEAD", "HEAD", "a") == ("HEAD (compiled)", "HEAD (pure)")
    assert labels("HEAD", "HEAD", None) == ("HEAD (A, pure)", "HEAD (B, pure)")
    assert labels("HEAD", "HEAD", "both") == ("HEAD (A, compiled)", "HEAD (B, compiled)")
