"""A signal at the very moment the program prints a line: no race with a loaded machine.

``interrupted(args, marker, sig)`` starts ``formationlab`` (as a shell does: SIGINT and
SIGTERM at their defaults) with its output (standard output and error, in one stream)
wrapped so that, once it has written a line that holds ``marker``, it waits on its
standard input. The test reads that line,
sends the signal and closes the input: the signal lands where the line was printed (a
handler that raises stops the wait; one that only notes the signal, while the program
holds signals, lets it go on at the end of input), however slow the machine. Waiting by
the clock, or racing the program to its next step, is what this replaces.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys

#: the child: the command line with standard error pausing after the marker's line
_CHILD = """\
import sys

class _Pausing:
    paused = False

    def __init__(self, stream, marker):
        self._stream, self._marker, self._line = stream, marker, ""

    def write(self, text):
        n = self._stream.write(text)
        self._line += text
        if "\\n" in self._line:
            done, _, self._line = self._line.rpartition("\\n")
            if not _Pausing.paused and self._marker in done:
                _Pausing.paused = True
                self._stream.flush()
                sys.stdin.readline()  # until the signal (or the end of input)
        return n

    def __getattr__(self, name):
        return getattr(self._stream, name)

marker = sys.argv.pop(1)
sys.stdout, sys.stderr = _Pausing(sys.stdout, marker), _Pausing(sys.stderr, marker)
from formationlab.cli import main
main()
"""


def _default_signals() -> None:
    """In the child: SIGINT and SIGTERM as a shell leaves them (default, not blocked)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})


def interrupted(
    args: list[str], marker: str, sig: int, *, env: dict[str, str] | None = None
) -> tuple[int, str]:
    """Run ``formationlab ARGS``, send ``sig`` when it has printed a line holding ``marker``;
    its exit status and its output (standard output and error)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", _CHILD, marker, *args],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        preexec_fn=_default_signals,
        env={**os.environ, "FORMATIONLAB_NO_WARMUP": "1", **(env or {})},
    )  # fmt: skip
    assert proc.stdout is not None
    seen = []
    for line in proc.stdout:
        seen.append(line)
        if marker in line:
            proc.send_signal(sig)
            break
    rest, _ = proc.communicate(timeout=600)  # (closes the input: a held signal goes on)
    out = "".join(seen) + rest
    assert marker in out, out
    return proc.returncode, out
