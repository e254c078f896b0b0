"""Block delete '/' of the lathe dialect (issue 32): a block starting with '/' is skipped while the block-delete
switch (the sequencer's input ``block_delete``) is on, else run. Fanuc reads the switch as it buffers a block; the
sequencer buffers (plans) the whole program at START, so the switch's value at START counts for the whole run."""

from __future__ import annotations

import pytest
from lathe_oracle import run_ideal

from ncfmu.controllers import CutSequencer
from ncfmu.controllers.gcode import read
from ncfmu.controllers.lathe_program import LATHE, Setup, parse
from ncfmu.controllers.rs274 import parse as mill_parse
from ncfmu.errors import ProgramError

PROGRAM = """%
O3001
N1 G21 G98 G8
N2 G00 X20. Z2.
/N3 G01 X15. F600.      (SKIPPED WITH THE SWITCH ON)
N4 G01 Z-5. F600.
(RETURN)  / N5 G00 X25.
N6 G00 X30. Z2.
M30
%
"""


def ends(text: str, deleting: bool) -> list[tuple[float, float]]:
    return [op.element.end for op in parse(text, (30.0, 2.0), Setup(diameter=False, block_delete=deleting))]


def test_slash_blocks_run_with_the_switch_off_and_are_skipped_with_it_on():
    assert ends(PROGRAM, False) == [(2.0, 20.0), (2.0, 15.0), (-5.0, 15.0), (-5.0, 25.0), (2.0, 30.0)]
    assert ends(PROGRAM, True) == [(2.0, 20.0), (-5.0, 20.0), (2.0, 30.0)]
    # the blocks read: the skipped ones are left out, the others keep their lines
    assert [b.line for b in read(PROGRAM, LATHE, True)] == [2, 3, 4, 6, 8, 9]


def test_a_slash_elsewhere_is_refused_and_a_deleted_block_is_checked_too():
    with pytest.raises(ProgramError) as err:
        parse("N1 G00 X20. /Z2.\nM30\n", (30.0, 2.0))
    assert (err.value.line_no, err.value.column) == (1, 13) and "stands at the start of a block" in str(err.value)
    for deleting in (False, True):          # an error in a block delete skips is an error either way
        with pytest.raises(ProgramError) as err:
            parse("N1 G00 X20.\n/N2 G01 Y5.\nM30\n", (30.0, 2.0), Setup(block_delete=deleting))
        assert (err.value.line_no, err.value.column) == (2, 9) and "no Y axis" in str(err.value)


def test_the_mill_dialect_still_refuses_block_delete():
    with pytest.raises(ProgramError) as err:
        mill_parse("/G01 X10 F100\nM30\n", (0.0, 0.0))
    assert err.value.column == 1 and "block delete '/' is not in the subset" in str(err.value)


def lowest_x(switch_at_start: bool, flip_at: int | None = None) -> float:
    seq = CutSequencer(program=PROGRAM, x_start=30.0, z_start=2.0, x_diameter=False)

    def events(k, inputs):
        inputs["block_delete"] = switch_at_start if flip_at is None or k < flip_at else not switch_at_start

    run = run_ideal(seq, events=events)
    assert run["done"][-1] and not run["alarm"].any()
    return float(run["x_cmd"].min())


def test_a_slash_after_a_comment_counts():
    from ncfmu.controllers.lathe_program import has_block_delete

    assert has_block_delete(PROGRAM) and has_block_delete("(A)/G00 X1.\nM30\n")
    assert not has_block_delete("G00 X1. (A/B)\nM30\n")


def test_the_sequencer_reads_the_switch_at_start():
    assert lowest_x(False) == pytest.approx(15.0, abs=1e-9)            # N3 ran: down to X15
    assert lowest_x(True) == pytest.approx(20.0, abs=1e-9)             # N3 skipped
    # switched after START: the program was buffered with the switch as it was then
    assert lowest_x(True, flip_at=5) == pytest.approx(20.0, abs=1e-9)
    assert lowest_x(False, flip_at=5) == pytest.approx(15.0, abs=1e-9)
