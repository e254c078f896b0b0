"""Ctrl-C and SIGTERM during a run: noted by a signal handler, raised by the master between chunks of steps --
or, where this process runs no FMU (a sweep's client waiting for its workers), raised at once, the first one only."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

__all__ = ["Interrupted", "deferred_interrupts", "handled_signals", "held_interrupts", "raise_pending",
           "raised_interrupts", "stopped_by"]

#: Signals noted inside :func:`deferred_interrupts`, raised by the loop between chunks of steps.
_PENDING: list[int] = []


class Interrupted(KeyboardInterrupt):
    """Ctrl-C or SIGTERM during a run, raised between chunks of steps (``signum`` says which)."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


@contextmanager
def handled_signals(signums: Sequence[int], handler: Any) -> Iterator[bool]:
    """Inside: ``handler`` (a function, or ``signal.SIG_IGN``) for each of ``signums``, the handlers of before
    restored after. Only the main thread can set them: elsewhere nothing changes. Yields whether they were set."""
    if threading.current_thread() is not threading.main_thread():
        yield False
        return
    previous = {signum: signal.signal(signum, handler) for signum in signums}
    try:
        yield True
    finally:
        for signum, before in previous.items():
            signal.signal(signum, before)


def _note(received: int, frame: object) -> None:
    _PENDING.append(received)


@contextmanager
def deferred_interrupts(signums: Sequence[int] = (signal.SIGINT, signal.SIGTERM)) -> Iterator[None]:
    """Inside: Ctrl-C and SIGTERM are noted and raised as :class:`Interrupted` by the master between chunks of
    steps, never inside an FMU's own Python code (a pythonfmu FMU runs in this interpreter and turns an
    exception raised in its step into fmi2Fatal). Only in the main thread; elsewhere nothing changes."""
    with handled_signals(signums, _note) as handled:
        try:
            yield
        finally:
            if handled:
                _PENDING.clear()


@contextmanager
def raised_interrupts(signums: Sequence[int] = (signal.SIGINT, signal.SIGTERM)) -> Iterator[None]:
    """Inside: the first Ctrl-C or SIGTERM raises :class:`Interrupted` in the main thread at once; later ones are
    only noted, so that what the first one set off -- closing a cluster, writing a summary -- runs to its end (a
    second Ctrl-C would leave worker processes and half a cleanup behind). For a main thread that runs no FMU's
    code (a pythonfmu FMU would turn the exception into fmi2Fatal: there :func:`deferred_interrupts`). Only in the
    main thread; elsewhere nothing changes."""
    def first(received: int, frame: object) -> None:
        for signum in signums:
            signal.signal(signum, _note)
        raise Interrupted(received)
    with deferred_interrupts(signums), handled_signals(signums, first):     # later ones: the outer's noting
        yield


@contextmanager
def held_interrupts(signums: Sequence[int] = (signal.SIGINT, signal.SIGTERM)) -> Iterator[None]:
    """Inside: a Ctrl-C or SIGTERM waits for the block's end, then is delivered as it would have been (to the
    handler of before: :func:`raised_interrupts`', Python's KeyboardInterrupt). For a step that, cut off, leaves
    what nothing can clean up (a dask cluster half started). Only in the main thread; elsewhere nothing changes."""
    held: list[int] = []
    try:
        with handled_signals(signums, lambda received, frame: held.append(received)):
            yield
    finally:
        if held:
            signal.raise_signal(held[0])


def stopped_by(err: BaseException) -> tuple[str, int]:
    """How a command says it was stopped by ``err`` (a KeyboardInterrupt, or :class:`Interrupted` for a signal)
    and its exit status: ``terminated (SIGTERM)``, 143; else ``interrupted``, 130 (128 + the signal's number)."""
    if isinstance(err, Interrupted) and err.signum == signal.SIGTERM:
        return "terminated (SIGTERM)", 143
    return "interrupted", 130


def raise_pending() -> None:
    """Raise :class:`Interrupted` for a signal noted since :func:`deferred_interrupts` began (the master calls this
    between chunks of steps)."""
    if _PENDING:
        raise Interrupted(_PENDING[0])
