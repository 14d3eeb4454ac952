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
ROOT_SEL = ".flv-root"


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


@contextmanager
def viewer_page(browser: Any, session: Any, **kwargs: Any) -> Iterator[Any]:
    """A page of the viewer of ``session``, ready (``data-state=ready``); the page must
    raise no error (``kwargs``: of ``browser.new_page``)."""
    with serving(session) as srv:
        page = browser.new_page(viewport={"width": 1100, "height": 720}, **kwargs)
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(srv.url)
        page.wait_for_selector(f"{ROOT_SEL}[data-state=ready]", timeout=15_000)
        yield page
        page.close()
        assert not errors, errors


def attr(page: Any, name: str) -> Any:
    """The page's ``data-NAME`` attribute (robots, frames, t, dim, ...)."""
    return page.get_attribute(ROOT_SEL, f"data-{name}")


def pause(page: Any, session: Any) -> None:
    """Pause from the page, and wait until it has drawn the paused state (the view, which
    follows the formation, then stays where it is)."""
    if not session.paused:
        page.click("button[data-role=pause]")
        wait_for(lambda: session.paused, what="the run to pause")
    wait_for(lambda: float(attr(page, "t")) == session.t, what="the paused state drawn")
