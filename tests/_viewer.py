"""Shared helpers of the viewer tests: an in-process server and Debian's chromium."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from formationlab.io.scenario import load_scenario
from formationlab.viewer import Controller, LiveSession
from formationlab.viewer.server import BackgroundServer

ROOT = Path(__file__).resolve().parents[1]
SIM2 = ROOT / "examples" / "paper-simulation-2.toml"
CHROMIUM = Path("/usr/bin/chromium")


def sim2_session(**kwargs: Any) -> LiveSession:
    return LiveSession(load_scenario(SIM2), seed=1, **kwargs)


@contextmanager
def serving(session: Any) -> Iterator[BackgroundServer]:
    """The viewer of ``session`` on a free loopback port, stopped at the end."""
    srv = BackgroundServer(Controller(session), host="127.0.0.1", port=0)
    srv.start()
    try:
        yield srv
    finally:
        srv.stop()


def wait_for(predicate: Callable[[], Any], timeout: float = 10.0, what: str = "") -> Any:
    """Poll ``predicate`` until it is truthy (bounded); fail with ``what`` otherwise."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.02)
    pytest.fail(f"timed out after {timeout:g} s waiting for {what or predicate}")


def launch_chromium(playwright: Any, *, webgl: bool = False) -> Any:
    """Debian's chromium, headless (``webgl``: with WebGL on SwiftShader, the software
    renderer, for the view of formations in space; headless chromium has no GPU here).

    Without it the browser tests skip, with the reason in pytest's summary, on a user's
    machine (the README's test command installs Python packages, not Debian's), and fail
    where ``CI`` is set: ``.ci/run`` installs chromium, so its absence there is a fault.
    """
    if not CHROMIUM.exists():
        why = (
            f"chromium not found at {CHROMIUM}: the browser tests need Debian's chromium "
            "(sudo apt-get install chromium; .ci/run installs it)"
        )
        if os.environ.get("CI"):
            pytest.fail(why)
        pytest.skip(why)
    args = ["--enable-unsafe-swiftshader", "--use-angle=swiftshader"] if webgl else []
    return playwright.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=args)
