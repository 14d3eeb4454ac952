"""An interactive viewer: watch, drag and tune a formation live, in the browser and in Jupyter.

``formationlab view SCENARIO`` serves a local page (:mod:`.server`) and
``formationlab.Viewer(scenario)`` shows the same front end as a notebook widget
(:mod:`.widget`). Both drive a :class:`~.session.LiveSession` (or a
:class:`~.replay.ReplaySession` of a saved run) through a
:class:`~.controller.Controller`, which validates the page's messages
(:mod:`.messages`). Needs the ``view`` extra: ``pip install formationlab[view]``.
"""

from __future__ import annotations

from typing import Any

from .controller import Controller, RateLimiter, Reply
from .replay import ReplaySession
from .session import LiveSession, SessionError

__all__ = [
    "Controller",
    "LiveSession",
    "RateLimiter",
    "ReplaySession",
    "Reply",
    "SessionError",
    "Viewer",
]


def __getattr__(name: str) -> Any:
    if name == "Viewer":  # needs anywidget; imported only when asked for
        from .widget import Viewer  # anywidget, the view extra: when asked for

        return Viewer
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
