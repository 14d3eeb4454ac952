"""Turn the page's messages into session commands and answers; shared by the server and the widget.

:class:`Controller` takes a raw message (text or bytes), validates it
(:func:`~formationlab.viewer.messages.parse_message`), applies it to the
session and returns the answers as :class:`Reply` objects; a bad message or a
refused command becomes an ``error`` reply, never an exception. The transport
(websocket or notebook widget) only moves replies. :class:`RateLimiter` is the
token bucket each connection puts in front of it.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ..errors import UserInputError
from . import messages as m
from .replay import ReplaySession
from .session import Frame, LiveSession

__all__ = ["Controller", "RateLimiter", "Reply"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Reply:
    """A message to the page: a JSON header and, for frames, binary buffers."""

    header: dict[str, Any]
    buffers: list[bytes] = field(default_factory=list)


def frame_reply(frame: Frame, seq: int) -> Reply:
    buffers = [frame.positions.astype("<f4").tobytes()]
    header = {"type": "frame", "seq": seq, **frame.header, "heading": frame.heading is not None}
    if frame.heading is not None:
        buffers.append(frame.heading.astype("<f4").tobytes())
    return Reply(header, buffers)


def error_reply(message: str, code: str = "bad-message") -> Reply:
    return Reply({"type": "error", "code": code, "message": message})


class Controller:
    """The protocol's server side for one session.

    Parameters
    ----------
    session : LiveSession or ReplaySession
    clock : callable
        Wall-clock seconds (``time.monotonic``; tests pass their own).
    max_wall_dt : float
        Most wall time one tick may advance the run by (a page that was in the
        background for a minute does not jump a minute ahead).
    """

    def __init__(
        self,
        session: LiveSession | ReplaySession,
        *,
        clock: Callable[[], float] = time.monotonic,
        max_wall_dt: float = 0.1,
    ) -> None:
        self.session = session
        self.clock = clock
        self.max_wall_dt = max_wall_dt
        self.seq = 0
        self._last: float | None = None
        #: callables run after every handled message (the widget syncs its traitlets there)
        self.listeners: list[Callable[[], None]] = []

    def hello(self) -> list[Reply]:
        """What a page gets when it connects: the static info and the first frame."""
        self._last = self.clock()
        return [Reply({"type": "info", **self.session.info()}), self._frame()]

    def _frame(self) -> Reply:
        self.seq += 1
        return frame_reply(self.session.frame(), self.seq)

    def handle(self, data: str | bytes) -> list[Reply]:
        """Answer one raw message from the page (never raises for bad input)."""
        try:
            msg = m.parse_message(data)
            replies = self._apply(msg)
        except UserInputError as exc:
            return [
                error_reply(
                    str(exc), "bad-message" if isinstance(exc, m.MessageError) else "refused"
                )
            ]
        except Exception as exc:  # a bug must not take the server down; it is logged
            log.exception("viewer: unexpected error while handling a message")
            return [error_reply(f"internal error ({type(exc).__name__}: {exc})", "internal")]
        for listener in self.listeners:
            listener()
        return replies

    def _apply(self, msg: Any) -> list[Reply]:
        s = self.session
        kind = msg.type
        if kind == "hello":
            return self.hello()
        if kind == "tick":
            now = self.clock()
            wall = 0.0 if self._last is None else min(now - self._last, self.max_wall_dt)
            self._last = now
            s.advance(wall)
            return [self._frame()]
        if kind == "pause":
            s.set_paused(msg.paused)
        elif kind == "step":
            s.step(msg.count)
        elif kind == "reset":
            s.reset()
        elif kind == "speed":
            s.set_speed(msg.value)
        elif kind == "drag":
            s.drag(msg.robot, msg.x, msg.y, msg.z)
        elif kind == "release":
            s.release()
        elif kind == "perturb":
            s.perturb(msg.scale)
        elif kind == "set_law":
            s.set_law(msg.name, dict(msg.params))
            return [self._info_update(), self._frame()]
        elif kind == "set_params":
            s.set_params(dict(msg.params))
            return [self._info_update(), self._frame()]
        elif kind == "set_integrator":
            s.set_integrator(msg.name, msg.dt)
            return [self._info_update(), self._frame()]
        elif kind == "export_scenario":
            filename, text = s.export_scenario()
            return [Reply({"type": "export", "filename": filename, "text": text})]
        elif kind == "seek":
            if not isinstance(s, ReplaySession):
                raise UserInputError("seek works in a replay only; this is a live run")
            s.seek(msg.index)
        return [self._frame()]

    def _info_update(self) -> Reply:
        """The parts of ``info`` a command changed (law, integrator, notices)."""
        info = self.session.info()
        keys = ("law", "integrator", "notices")
        return Reply({"type": "settings", **{k: info[k] for k in keys if k in info}})


class RateLimiter:
    """Token bucket: ``rate`` messages per second on average, bursts of ``burst``.

    :meth:`allow` says whether a message may pass; :meth:`should_warn` whether
    to tell the page that messages were dropped (at most once per second).
    """

    def __init__(
        self, rate: float = 200.0, burst: float = 400.0, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.rate, self.burst, self.clock = rate, burst, clock
        self.tokens = burst
        self.stamp = clock()
        self.dropped = 0
        self._warned = -1e9

    def allow(self) -> bool:
        now = self.clock()
        self.tokens = min(self.burst, self.tokens + (now - self.stamp) * self.rate)
        self.stamp = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        self.dropped += 1
        return False

    def should_warn(self) -> bool:
        now = self.clock()
        if now - self._warned >= 1.0:
            self._warned = now
            return True
        return False
