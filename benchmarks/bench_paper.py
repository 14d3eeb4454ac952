"""Wall time of ``formationlab paper`` (the whole reproduction, figures included).

Runs ``formationlab paper --out DIR`` in a fresh output folder, as a user would, ``--repeat``
times (default 3) and prints each wall time, the best, and the CPU time of the command; the
target is at most 10 s of wall time on 2 cores. The numba caches are whatever this checkout
holds (the first run after an install compiles: run the benchmark twice to see both).

Absolute times drift with the load of a shared machine, so the load average is printed
before and after, and two references are measured in the same run: the wall time of
``python -c "import formationlab"`` (best of three) and of a fixed numpy workload
(``REFERENCE``, best of three, in this process); the ratios of the paper's time to them
scale a figure from a busy machine to a quiet one.

``--phases`` adds the same work timed phase by phase in one process (imports, the three
runs, the scans, the summary, the figures).

Run ``python benchmarks/bench_paper.py [--repeat 3] [--phases]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def formationlab_command() -> list[str]:
    """The ``formationlab`` of this interpreter's environment."""
    exe = Path(sys.executable).with_name("formationlab")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "formationlab.cli"]


def reference_workload() -> float:
    """Best of three: seconds of a fixed numpy workload (sorting and FFTs, one thread)."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=2_000_000)
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        for _ in range(5):
            np.sort(x)
            np.fft.rfft(x)
        best = min(best, time.perf_counter() - t)
    return best


def import_time() -> float:
    """Best of three: wall seconds of ``python -c "import formationlab"``."""
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import formationlab"], check=True)
        best = min(best, time.perf_counter() - t)
    return best


def one_paper(cmd: list[str]) -> tuple[float, float]:
    """Wall and CPU seconds (user + system) of ``formationlab paper`` into a fresh folder."""
    out = Path(tempfile.mkdtemp(prefix="paper-"))
    shutil.rmtree(out)  # a folder that does not exist yet, as a first run makes it
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run([*cmd, "paper", "--out", str(out)], check=True, capture_output=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    shutil.rmtree(out, ignore_errors=True)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def phases() -> None:
    """The reproduction timed phase by phase in this process."""
    t = time.perf_counter()
    from formationlab.studies.paper import PaperSetup, reproduce

    print(f"  import formationlab          {time.perf_counter() - t:6.2f} s")
    setup = PaperSetup()
    t = time.perf_counter()
    rep = reproduce(setup)
    print(f"  reproduce (3 runs, 25 scans) {time.perf_counter() - t:6.2f} s")
    t = time.perf_counter()
    rep.summary()
    print(f"  summary                      {time.perf_counter() - t:6.2f} s")
    t = time.perf_counter()
    from formationlab.io import save_figure
    from formationlab.plotting.paper import paper_figures

    print(f"  import plotting              {time.perf_counter() - t:6.2f} s")
    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for stem, fig in paper_figures(rep).items():
            save_figure(fig, Path(tmp, f"{stem}.png"))
    print(f"  11 figures                   {time.perf_counter() - t:6.2f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--phases", action="store_true")
    args = parser.parse_args()
    cmd = formationlab_command()
    load = os.getloadavg()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
    ref_import = import_time()
    ref_numpy = reference_workload()
    print(f"reference: `python -c 'import formationlab'` {ref_import:.2f} s, "
          f"numpy workload {ref_numpy:.2f} s (best of 3)")  # fmt: skip
    walls = []
    for k in range(args.repeat):
        wall, cpu = one_paper(cmd)
        walls.append(wall)
        print(f"formationlab paper, run {k + 1}: {wall:6.2f} s wall, {cpu:6.2f} s CPU", flush=True)
    best = min(walls)
    print(f"best {best:.2f} s wall (target <= 10 s); {best / ref_import:.1f}x the import, "
          f"{best / ref_numpy:.1f}x the numpy workload")  # fmt: skip
    if args.phases:
        print("phases, in one process:")
        phases()
    print(f"load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
