"""Ctrl-C and SIGTERM on the command line: the same way to stop, a status that says which.

:func:`install` (called by :func:`formationlab.cli.main`) makes SIGINT and SIGTERM raise
KeyboardInterrupt, so that a ``kill`` stops a run the way Ctrl-C does (the states so far
written, status ``interrupted``), and notes which signal came: the command then exits
with ``128 +`` its number (:func:`interrupted_status`: 130 for Ctrl-C, 143 for SIGTERM),
as a shell reports a program a signal ended. A signal that comes while numba loads or
compiles a kernel is sent again a tenth of a second later (raised there, it would leave
the kernel unusable). A signal that comes as the command ends, once its work is done
(:func:`ended`), is not lost either: the command exits ``128 +`` its number and says that
what it wrote is whole.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from types import FrameType
from typing import Any, NoReturn

__all__ = [
    "AFTER_THE_WORK",
    "command_done",
    "ended",
    "exit_interrupted",
    "install",
    "interrupted_status",
    "is_done",
]

#: the signals received by this command, in order
_received: list[int] = []

#: the handlers in place before :func:`install`, restored by :func:`ended`
_previous: dict[int, Any] = {}

#: whether the command's own work has ended (:func:`command_done`)
_done: list[bool] = []

#: what is said of a signal that came once the command's work was done
AFTER_THE_WORK = "interrupted as the command ended; what it wrote is whole (as it said above)"


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
    _done.clear()
    for sig in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(sig)
        if handler is not signal.SIG_IGN:  # (nohup and the like ignore them)
            _previous[sig] = handler
            signal.signal(sig, _interrupt)


def command_done(done: bool = True) -> None:
    """Note that the command's own work has ended (its files written, its verdict said): a
    signal from now on is said to have come after it (:data:`AFTER_THE_WORK`); ``False``
    as a command starts."""
    _done.clear()
    if done:
        _done.append(True)


def is_done() -> bool:
    """Whether the command's own work has ended (:func:`command_done`)."""
    return bool(_done)


def _note(signum: int, frame: FrameType | None) -> None:
    _received.append(signum)


def ended(status: Any, *, process: bool) -> Any:
    """The exit status of a command that ended with ``status``, with a signal that came as it
    ended: ``128 +`` the signal, and :data:`AFTER_THE_WORK` said, when one came that no
    interrupt reported (after the command's last step, or swallowed on the way out).

    From here on the handlers in place before :func:`install` are back, and for the
    process's own command line (``process``) a signal ends the process as a shell expects
    (its default action: the shell reports ``128 +`` its number).
    """
    if threading.current_thread() is not threading.main_thread():
        return status
    while True:  # only noted from here (signal.signal first runs a pending one's handler)
        try:
            for sig in _previous:
                signal.signal(sig, _note)
            break
        except KeyboardInterrupt:
            continue  # (noted by the handler that raised it)
    for sig, handler in _previous.items():
        signal.signal(sig, signal.SIG_DFL if process else handler)
    _previous.clear()
    if not _received or status == interrupted_status():
        return status
    print(AFTER_THE_WORK if _done else "interrupted", file=sys.stderr)
    return interrupted_status()


def interrupted_status() -> int:
    """``128 +`` the last signal received (130 when none was noted: a Ctrl-C)."""
    return 128 + (_received[-1] if _received else signal.SIGINT)


def exit_interrupted() -> NoReturn:
    """End the command outside its error handling (before it, or after its work): one line,
    no traceback."""
    print(AFTER_THE_WORK if _done else "interrupted", file=sys.stderr)
    raise SystemExit(interrupted_status())
