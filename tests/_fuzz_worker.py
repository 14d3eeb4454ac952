"""The scenario fuzzer's worker: formationlab's commands in one process, request by request.

``python tests/_fuzz_worker.py FD`` imports the command line once, then reads one JSON
request per line on standard input (``{"args": [...]}``), runs the command in-process with
typer's ``CliRunner`` and writes one JSON reply per line to the file descriptor ``FD`` (not
standard output, which the commands and the programs they start may write to):
``{"exit": status, "output": text, "error": traceback or null, "warnings": [...],
"seconds": wall time}``. ``error`` is the traceback of any exception other than the
``SystemExit`` of an exit status; ``warnings`` lists every warning that is not one of
formationlab's own (which the commands print as ``warning:`` lines).

The parent (``tests/_fuzz.py``) starts it under a memory limit and a timeout: a worker that
dies (abort, out of memory) or hangs is the finding.
"""

from __future__ import annotations

import json
import os
import sys
import time
import traceback
import warnings


def main() -> None:
    reply = os.fdopen(int(sys.argv[1]), "w", encoding="utf-8")
    from typer.testing import CliRunner

    from formationlab.cli import _load_commands, app
    from formationlab.errors import FormationlabWarning

    _load_commands()
    runner = CliRunner()
    reply.write(json.dumps({"ready": True}) + "\n")
    reply.flush()
    for line in sys.stdin:
        request = json.loads(line)
        start = time.perf_counter()
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            result = runner.invoke(app, request["args"])
        exc = result.exception
        error = None
        if exc is not None and not isinstance(exc, SystemExit):
            error = "".join(traceback.format_exception(exc))
        stray = [
            f"{w.category.__name__}: {w.message} ({w.filename}:{w.lineno})"
            for w in seen
            if not issubclass(w.category, FormationlabWarning)
        ]
        answer = {
            "exit": result.exit_code,
            "output": result.output,
            "error": error,
            "warnings": stray,
            "seconds": time.perf_counter() - start,
        }
        reply.write(json.dumps(answer) + "\n")
        reply.flush()


if __name__ == "__main__":
    main()
