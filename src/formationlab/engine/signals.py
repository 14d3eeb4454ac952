"""Ctrl-C and SIGTERM held while a compiled segment runs (or a file is written whole), and
delivered after it.

A signal that arrives inside numba code runs its Python handler as the compiled function
hands its results back; a KeyboardInterrupt raised there became a ``SystemError`` and the
results were lost. The compiled single run (:mod:`formationlab.integrators.compiled`) holds
them between its segments, and ``formationlab run`` while it writes a finished simulation.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["held_signals"]


@contextmanager
def held_signals() -> Iterator[Callable[[], None]]:
    """Hold SIGINT and SIGTERM inside the block; ``deliver()`` them when it is safe (between
    compiled segments).

    A signal that arrives inside numba code runs its Python handler as the segment hands its
    results back: Ctrl-C's KeyboardInterrupt raised there became a ``SystemError`` ("returned
    a result with an exception set") and the run was lost. Inside the block the handlers
    only note the signal, and ``deliver()`` calls the handler that was in place (for
    Ctrl-C, Python's: KeyboardInterrupt). Only in the main thread (where signals are
    handled) and for handlers that are Python functions; restored on leaving (a signal
    held then is raised again, unless the block ended with an exception).
    """
    held: list[tuple[int, Any]] = []
    previous: dict[int, Callable[[int, Any], Any]] = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            handler = signal.getsignal(sig)
            if callable(handler):
                previous[sig] = handler
                signal.signal(sig, lambda s, frame: held.append((s, frame)))

    def deliver() -> None:
        while held:  # delivered here and now: from the caller's frame
            sig, _ = held.pop(0)
            previous[sig](sig, sys._getframe(1))

    try:
        yield deliver
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    for sig, _ in held:  # one that came after the last delivery: as if it came now
        signal.raise_signal(sig)
