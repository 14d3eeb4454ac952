import os
import subprocess
import sys
import time
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")


def pytest_configure(config: pytest.Config) -> None:
    """Compile the numba kernels once, in two processes, before the test workers start.

    Without it every worker compiles every kernel it meets (the same minutes of compilation
    paid once per worker). Only the controlling process of a parallel run does it; a
    serial run or a worker skips it, and ``FORMATIONLAB_NO_WARMUP=1`` turns it off.
    """
    if hasattr(config, "workerinput") or os.environ.get("FORMATIONLAB_NO_WARMUP"):
        return
    if not getattr(config.option, "numprocesses", None):
        return
    start = time.perf_counter()
    script = Path(__file__).with_name("_warmup.py")
    procs = [
        subprocess.Popen([sys.executable, str(script), part], stderr=subprocess.PIPE, text=True)
        for part in ("0", "1")
    ]
    for p in procs:
        _, err = p.communicate()
        if p.returncode:  # the tests themselves will show what is wrong
            _WARMUP.append(f"numba warm-up part failed:\n{err[-2000:]}")
    _WARMUP.append(f"numba kernels warmed in {time.perf_counter() - start:.0f} s")


#: what the warm-up has to say, printed at the end of the run
_WARMUP: list[str] = []


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    for line in _WARMUP:
        terminalreporter.write_line(line)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)
