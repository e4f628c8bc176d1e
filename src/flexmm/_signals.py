"""SIGTERM stops a run the way Ctrl-C does: cleanly, keeping what is good.

Batch schedulers and ``timeout`` send SIGTERM; Python's default is to die on the spot, losing
every frame. Inside ``stop_on_signals()`` (installed by the CLI in the main thread) SIGTERM
raises ``Terminated``, a ``KeyboardInterrupt``, so every loop that already stops cleanly on
Ctrl-C (the ``Stepper``, sweeps) stops on SIGTERM too. ``exit_status`` gives the shell's
convention, 128 + the signal number: 130 for SIGINT, 143 for SIGTERM.
"""

from __future__ import annotations

import signal
import threading

import _signal  # signal's C module: its signal() without signal.py's enum conversions (``deferred``)
from collections.abc import Iterator
from contextlib import contextmanager


class Terminated(KeyboardInterrupt):
    """Raised by the SIGTERM handler of ``stop_on_signals``."""

    signum = signal.SIGTERM


def signal_of(exc: BaseException) -> int:
    """The signal behind an interruption: SIGTERM for ``Terminated``, else SIGINT."""
    return int(getattr(exc, "signum", signal.SIGINT))


def exit_status(signum: int) -> int:
    """128 + signal number (130 after SIGINT, 143 after SIGTERM)."""
    return 128 + int(signum)


def _raise_terminated(signum, frame) -> None:
    raise Terminated()


@contextmanager
def stop_on_signals() -> Iterator[None]:
    """SIGTERM raises ``Terminated`` inside the block (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


class _Deferred:
    """The handlers ``deferred`` installs: a signal is noted, and acted on when the block ends."""

    def __init__(self) -> None:
        self.noted: list[int] = []

    def __call__(self, signum, frame) -> None:
        self.noted.append(signum)


@contextmanager
def deferred() -> Iterator[None]:
    """SIGINT and SIGTERM wait until the block ends (main thread only; elsewhere a no-op).

    Inside, a signal is only noted; when the block ends the handlers in force before it are back
    and the first signal noted is raised again (``signal.raise_signal``), so it acts as it would
    have: a ``KeyboardInterrupt`` or ``Terminated`` — after the block, never inside it. The
    ``Stepper`` wraps each compiled call (state, time and counters change together) and each
    frame's checks and observers in one, so an interruption leaves a state a checkpoint can
    continue from bit for bit."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    note = _Deferred()
    # the C module's signal(): the Stepper enters this block twice a frame, and signal.signal's
    # conversion of every handler to an enum (an exception caught per call) cost 16 µs a block
    previous = ((_SIGINT, _signal.signal(_SIGINT, note)), (_SIGTERM, _signal.signal(_SIGTERM, note)))
    try:
        yield
    finally:
        for s, handler in previous:
            _signal.signal(s, _signal.SIG_DFL if handler is None else handler)
        if note.noted:
            signal.raise_signal(note.noted[0])


_SIGINT, _SIGTERM = int(signal.SIGINT), int(signal.SIGTERM)


@contextmanager
def absorbed() -> Iterator[None]:
    """SIGINT and SIGTERM do nothing inside the block (main thread only; elsewhere a no-op): a run
    already stopping on one writes what it keeps — its last frames, its final checkpoint — whole,
    however often Ctrl-C is pressed again (a sweep sends it to its workers until they return)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, _Deferred()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
