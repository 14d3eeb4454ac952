"""The ``formationlab`` command's first second: Ctrl-C or SIGTERM while the package loads.

The console script imports the package (numpy, scipy, numba, the kernels: about a second)
before the command line's handling of Ctrl-C is in place, and a Ctrl-C then printed a
KeyboardInterrupt traceback. When the program is that script (``sys.argv[0]`` is a file
named ``formationlab``), SIGINT and SIGTERM end it with ``interrupted`` and status
130 or 143 until :func:`formationlab.cli.main` installs its own handlers. Imported as a
library, nothing changes.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from types import FrameType

__all__: list[str] = []


def _stop(signum: int, frame: FrameType | None) -> None:
    print("interrupted", file=sys.stderr)
    raise SystemExit(128 + signum)


def _started_as_the_command() -> bool:
    return bool(sys.argv) and os.path.basename(sys.argv[0] or "") == "formationlab"


if _started_as_the_command() and threading.current_thread() is threading.main_thread():
    for _sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(_sig) is not signal.SIG_IGN:
            signal.signal(_sig, _stop)
