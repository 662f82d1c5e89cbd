"""SIGTERM as a polite stop: the run stops at its next safe point, like on Ctrl-C.

A process manager (a cluster pre-empting a worker, ``timeout``, ``kill``) sends SIGTERM.
Inside :func:`sigterm_as_keyboard_interrupt` the handler only remembers the signal; the
run calls :func:`raise_if_stop_requested` at its safe points (every environment step,
every optimiser iteration, between phases), which raises ``KeyboardInterrupt`` there. An
exception raised by the handler itself could land in a library's finaliser or weak
reference callback, where Python drops it.
"""
from __future__ import annotations

import contextlib
import signal
from typing import Iterator, Optional

from ..runtime import signal_handler

__all__ = ["sigterm_as_keyboard_interrupt", "stop_requested", "raise_if_stop_requested",
           "interrupts_deferred", "signal_handler"]

#: number of the termination signal received inside ``sigterm_as_keyboard_interrupt``
_stop_signal: Optional[int] = None


def stop_requested() -> bool:
    """True once SIGTERM arrived inside :func:`sigterm_as_keyboard_interrupt`."""
    return _stop_signal is not None


def raise_if_stop_requested() -> None:
    """Raise ``KeyboardInterrupt`` if SIGTERM arrived (call at the run's safe points)."""
    if _stop_signal is not None:
        raise KeyboardInterrupt(f"signal {_stop_signal}")


@contextlib.contextmanager
def sigterm_as_keyboard_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM stops the run like Ctrl-C, at the next safe point.

    The previous handler is restored afterwards. Only the main thread can install signal
    handlers; elsewhere this does nothing.
    """
    global _stop_signal

    def handler(signum, frame):  # signal handler signature
        global _stop_signal
        _stop_signal = signum

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread
        yield
        return
    _stop_signal = None
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
        _stop_signal = None


def interrupts_deferred():
    """Ignore Ctrl-C within the block (a second Ctrl-C while saving must not lose data)."""
    return signal_handler(signal.SIGINT, signal.SIG_IGN)
