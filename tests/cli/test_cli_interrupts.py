"""Ctrl-C before a command's work has begun, and a sweep stopped before any variant finished: one line, exit 130."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

from ncfmu import batch, cli
from ncfmu.batch import SweepStopped
from ncfmu.cli import main


def stderr_lines(capsys) -> list[str]:
    return [line for line in capsys.readouterr().err.splitlines() if line.strip()]


@pytest.mark.parametrize("command", [["run", "lathe_taper"], ["sweep", "lathe_taper", "--vary", "seq.block[1].Xd=0.4"]])
def test_ctrl_c_while_the_options_are_read_is_one_line(tmp_path, monkeypatch, capsys, command):
    """A Ctrl-C in the first moments (imports, the options checked, a --replace'd system prepared) was Python's
    KeyboardInterrupt traceback."""
    def pressed(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(cli, "_build_kind", pressed)
    assert main([*command, "--out", str(tmp_path)]) == 130
    assert stderr_lines(capsys) == [f"ncfmu {command[0]}: interrupted"]


def test_a_sweep_stopped_before_any_variant_finished_names_no_summary(tmp_path, monkeypatch, capsys):
    """Nothing finished, no summary written: the line names none (it named DIR/summary.csv, which did not exist)."""
    def stopped(system, vary, out, **kwargs):
        raise SweepStopped(signal.SIGTERM, 0, 16, Path(out) / "summary.csv")
    monkeypatch.setattr(batch, "sweep", stopped)
    with pytest.raises(SystemExit) as exit_:
        main(["sweep", "lathe_taper", "--vary", "seq.block[1].Xd=0.4", "--workers", "0", "--out", str(tmp_path)])
    assert exit_.value.code == 143
    assert stderr_lines(capsys) == ["ncfmu sweep: terminated (SIGTERM): 0 of 16 variants done; the same command "
                                    "runs them"]
