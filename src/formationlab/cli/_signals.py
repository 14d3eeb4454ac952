"""Ctrl-C and SIGTERM on the command line: the same way to stop, a status that says which.

:func:`install` (called by :func:`formationlab.cli.main`) makes SIGINT and SIGTERM raise
KeyboardInterrupt, so that a ``kill`` stops a run the way Ctrl-C does (the states so far
written, status ``interrupted``), and notes which signal came: the command then exits
with ``128 +`` its number (:func:`interrupted_status`: 130 for Ctrl-C, 143 for SIGTERM),
as a shell reports a program a signal ended. A signal that comes while numba loads or
compiles a kernel is sent again a tenth of a second later (raised there, it would leave
the kernel unusable).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from types import FrameType
from typing import NoReturn

__all__ = ["exit_interrupted", "install", "interrupted_status"]

#: the signals received by this command, in order
_received: list[int] = []


#: seconds after which a signal that came while numba was loading a kernel is sent again
_AGAIN = 0.1


def _in_numba(frame: FrameType | None) -> bool:
    """Whether numba or llvmlite is on the stack (compiling, or loading a cached kernel)."""
    while frame is not None:
        path = frame.f_code.co_filename
        if f"{os.sep}numba{os.sep}" in path or f"{os.sep}llvmlite{os.sep}" in path:
            return True
        frame = frame.f_back
    return False


def _interrupt(signum: int, frame: FrameType | None) -> None:
    _received.append(signum)
    if _in_numba(frame):
        # an exception raised there is swallowed (a ctypes callback) and leaves the kernel
        # unusable ("no compiled object yet"): the signal is sent again shortly
        threading.Timer(_AGAIN, os.kill, (os.getpid(), signum)).start()
        return
    raise KeyboardInterrupt


def install() -> None:
    """SIGINT and SIGTERM raise KeyboardInterrupt (in the main thread; elsewhere nothing)."""
    if threading.current_thread() is not threading.main_thread():
        return
    _received.clear()
    for sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(sig) is not signal.SIG_IGN:  # (nohup and the like ignore them)
            signal.signal(sig, _interrupt)


def interrupted_status() -> int:
    """``128 +`` the last signal received (130 when none was noted: a Ctrl-C)."""
    return 128 + (_received[-1] if _received else signal.SIGINT)


def exit_interrupted() -> NoReturn:
    """End the command before its error handling is in place: one line, no traceback."""
    print("interrupted", file=sys.stderr)
    raise SystemExit(interrupted_status())
