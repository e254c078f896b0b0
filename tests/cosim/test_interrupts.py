"""A Ctrl-C held over a step that must not be cut off: delivered at its end, as it would have been."""

from __future__ import annotations

import os
import signal

import pytest

from ncfmu.cosim.interrupts import Interrupted, held_interrupts, raised_interrupts


def test_a_held_ctrl_c_is_delivered_at_the_blocks_end_to_the_handler_of_before():
    steps = []
    with pytest.raises(KeyboardInterrupt):          # Python's own handler, as a plain script has it
        with held_interrupts():
            os.kill(os.getpid(), signal.SIGINT)
            steps.append("after the signal")        # the block runs to its end
    assert steps == ["after the signal"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_held_sigterm_inside_raised_interrupts_stops_with_its_number():
    with pytest.raises(Interrupted) as stopped:
        with raised_interrupts(), held_interrupts():
            os.kill(os.getpid(), signal.SIGTERM)
            os.kill(os.getpid(), signal.SIGINT)     # a second one: the first one only
    assert stopped.value.signum == signal.SIGTERM


def test_nothing_held_nothing_raised():
    with held_interrupts():
        pass
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
