"""The first run after an install: ``formationlab paper`` and ``formationlab run
examples/hexagon.toml`` with an empty numba cache, then again with the cache they filled.

Each command runs in a fresh process with ``NUMBA_CACHE_DIR`` set to a new, empty folder
(numba then neither reads nor writes the checkout's own cache), as on a fresh install; then
once more with that folder as it left it (the warm time). Printed per command: wall time,
the CPU time of the process (compiling is single-threaded, so on a busy machine the CPU time
is the better measure of what a quiet one would take), and the time numba spent compiling
(from numba's compile events, in the process). The target (issue "single runs on the
engine's loop", item 4): each first run within 20 s on 2 cores.

Absolute times drift with the load of a shared machine: the load average is printed, and the
wall time of ``python -c "import formationlab"`` (best of three) as a reference measured in
the same run.

Run ``python benchmarks/bench_first_run.py``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: run in the child: the command, timed, with numba's compile time from its events
CHILD = r"""
import json, resource, sys, time
from numba.core import event
spent = [0.0, 0, 0.0]  # seconds compiling, depth, start

class Compiles(event.Listener):
    def on_start(self, e):
        if spent[1] == 0:
            spent[2] = time.perf_counter()
        spent[1] += 1
    def on_end(self, e):
        spent[1] -= 1
        if spent[1] == 0:
            spent[0] += time.perf_counter() - spent[2]

event.register("numba:compile", Compiles())
start = time.perf_counter()
from formationlab.cli import main
try:
    main(sys.argv[1:])
except SystemExit as e:
    code = e.code
else:
    code = 0
ru = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"wall": time.perf_counter() - start, "cpu": ru.ru_utime + ru.ru_stime,
                  "compile": spent[0], "code": code}))
"""


def timed(args: list[str], cache: str, out: Path) -> dict:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    begun = time.perf_counter()
    p = subprocess.run(
        [sys.executable, "-c", CHILD, *args, "--out", str(out)],
        env=env, cwd=ROOT, capture_output=True, text=True, check=False,
    )  # fmt: skip
    wall = time.perf_counter() - begun
    lines = [s for s in p.stdout.splitlines() if s.startswith("{")]
    if p.returncode or not lines:
        sys.exit(f"{' '.join(args)} failed:\n{p.stdout[-2000:]}\n{p.stderr[-2000:]}")
    figures = json.loads(lines[-1])
    figures["process"] = wall  # with the interpreter's start
    return figures


def import_time() -> float:
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import formationlab"], check=True, cwd=ROOT)
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    print(f"load average before: {os.getloadavg()}")
    ref = import_time()
    print(f"reference: python -c 'import formationlab' {ref:.2f} s (best of 3)")
    commands = {
        "formationlab paper": ["paper"],
        "formationlab run examples/hexagon.toml": ["run", "examples/hexagon.toml"],
    }
    print(f"{'command':42s} {'':6s} {'process':>8s} {'CPU':>7s} {'compile':>8s}")
    for name, args in commands.items():
        with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as tmp:
            for label in ("first", "warm"):
                out = Path(tmp) / label
                f = timed(args, cache, out)
                print(
                    f"{name:42s} {label:6s} {f['process']:7.1f}s {f['cpu']:6.1f}s "
                    f"{f['compile']:7.1f}s"
                )
    print(f"load average after: {os.getloadavg()}")
    print("target: the first run of each within 20 s on 2 cores (process time)")


if __name__ == "__main__":
    main()
