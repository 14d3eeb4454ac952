"""The viewer's local web server (Starlette on uvicorn): the page, its script, and a websocket.

Safe by default: it binds to 127.0.0.1, every URL that reveals or changes the
run needs the random token that :func:`make_token` draws (``/?token=...`` and
the websocket ``/ws?token=...``; a wrong or missing token gets 403 and the
websocket is refused, as is a websocket whose ``Origin`` is not the viewer's own page),
each connection is rate-limited, messages are validated
(:mod:`formationlab.viewer.messages`), and the server writes no file: exports
are sent to the page, which downloads them. The page's static files carry no
data and are served without the token.
"""

from __future__ import annotations

import asyncio
import logging
import secrets
import socket
import threading
from typing import Any
from urllib.parse import urlsplit

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import HTMLResponse, PlainTextResponse, Response
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect

from .assets import bundle, read_asset, three_module
from .controller import Controller, RateLimiter, Reply, error_reply
from .messages import dumps, encode_binary

__all__ = ["BackgroundServer", "make_app", "make_token", "uvicorn_server"]

log = logging.getLogger(__name__)

#: uvicorn closes a websocket whose message is longer than this (code 1009); messages
#: between MAX_MESSAGE_BYTES and this are read and answered with an error instead.
WS_MAX_SIZE = 16 * 1024 * 1024


def make_token() -> str:
    """A random URL-safe token (128 bits)."""
    return secrets.token_urlsafe(16)


def _headers(csp_connect: str = "") -> dict[str, str]:
    return {
        "Content-Security-Policy": (
            "default-src 'self'; img-src 'self' data: blob:; style-src 'self'; "
            f"connect-src 'self' {csp_connect}".strip()
        ),
        "X-Content-Type-Options": "nosniff",
        "Referrer-Policy": "no-referrer",
        "Cache-Control": "no-store",
    }


def _origin_ok(origin: str | None, host: str | None) -> bool:
    """Whether a websocket's ``Origin`` is the viewer's own page: a browser always sends it,
    and a page of another site (cross-site websocket hijacking, should it learn the token)
    has another; a client that is not a browser sends none and is judged by the token."""
    if origin is None:
        return True
    parts = urlsplit(origin)
    return parts.scheme in ("http", "https") and host is not None and parts.netloc == host


def make_app(controller: Controller, token: str) -> Starlette:
    """The Starlette application serving ``controller``'s session to pages holding ``token``."""
    lock = asyncio.Lock()

    def _token_ok(value: str | None) -> bool:
        return value is not None and secrets.compare_digest(value.encode(), token.encode())

    async def index(request: Request) -> Response:
        if not _token_ok(request.query_params.get("token")):
            return PlainTextResponse(
                "403: this viewer needs the token from the URL that `formationlab view` printed",
                status_code=403,
            )
        host = request.headers.get("host", "")
        return HTMLResponse(read_asset("index.html"), headers=_headers(f"ws://{host}"))

    async def script(request: Request) -> Response:
        return Response(bundle(), media_type="text/javascript", headers=_headers())

    async def page(request: Request) -> Response:
        return Response(read_asset("page.js"), media_type="text/javascript", headers=_headers())

    async def three(request: Request) -> Response:
        try:
            text = three_module(request.path_params["name"])
        except KeyError:
            return PlainTextResponse("404: no such file", status_code=404)
        headers = {**_headers(), "Cache-Control": "max-age=86400"}  # a vendored release
        return Response(text, media_type="text/javascript", headers=headers)

    async def style(request: Request) -> Response:
        name = request.url.path.lstrip("/")
        return Response(read_asset(name), media_type="text/css", headers=_headers())

    async def no_icon(request: Request) -> Response:
        return Response(status_code=204)

    async def send(ws: WebSocket, reply: Reply) -> None:
        if reply.buffers:
            await ws.send_bytes(encode_binary(reply.header, reply.buffers))
        else:
            await ws.send_text(dumps(reply.header))

    async def stream(ws: WebSocket) -> None:
        if not _token_ok(ws.query_params.get("token")):
            await ws.close(code=4403, reason="wrong or missing token")
            return
        if not _origin_ok(ws.headers.get("origin"), ws.headers.get("host")):
            await ws.close(code=4403, reason="a page of another site may not drive this viewer")
            return
        await ws.accept()
        limiter = RateLimiter()
        try:
            while True:
                event = await ws.receive()
                if event["type"] == "websocket.disconnect":
                    break
                data = event.get("text")
                if data is None:
                    data = event.get("bytes") or b""
                if not limiter.allow():
                    if limiter.should_warn():
                        await send(
                            ws,
                            error_reply(
                                f"too many messages: {limiter.dropped} dropped so far (at most "
                                f"{limiter.rate:g} per second are handled)",
                                "rate-limited",
                            ),
                        )
                    continue
                async with lock:  # one session, possibly several pages
                    replies = await asyncio.to_thread(controller.handle, data)
                for reply in replies:
                    await send(ws, reply)
        except WebSocketDisconnect:
            pass

    return Starlette(
        routes=[
            Route("/", index),
            Route("/app.js", script),
            Route("/page.js", page),
            Route("/three/{name}", three),
            Route("/viewer.css", style),
            Route("/page.css", style),
            Route("/favicon.ico", no_icon),
            WebSocketRoute("/ws", stream),
        ]
    )


def uvicorn_server(app: Starlette, *, log_level: str = "warning") -> Any:
    """A ``uvicorn.Server`` for ``app`` (run it with ``server.run(sockets=[sock])``)."""
    import uvicorn

    config = uvicorn.Config(
        app,
        log_level=log_level,
        ws="websockets-sansio",
        ws_max_size=WS_MAX_SIZE,
        lifespan="off",
        access_log=False,
    )
    return uvicorn.Server(config)


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port`` (port 0: a free one)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    sock.listen(64)
    sock.setblocking(False)
    return sock


class BackgroundServer:
    """The viewer served from a thread of this process (tests, benchmarks, notebooks).

    ``with BackgroundServer(controller) as srv: ... srv.url ...``; the server
    stops when the block ends.
    """

    def __init__(self, controller: Controller, *, host: str = "127.0.0.1", port: int = 0) -> None:
        self.controller = controller
        self.token = make_token()
        self.sock = bind(host, port)
        self.host, self.port = self.sock.getsockname()[:2]
        self.server = uvicorn_server(make_app(controller, self.token))
        self.thread = threading.Thread(
            target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True
        )

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/?token={self.token}"

    @property
    def ws_url(self) -> str:
        return f"ws://{self.host}:{self.port}/ws?token={self.token}"

    def start(self, timeout: float = 10.0) -> BackgroundServer:
        self.thread.start()
        for _ in range(int(timeout / 0.01)):
            if self.server.started:
                return self
            if not self.thread.is_alive():
                break
            threading.Event().wait(0.01)
        raise RuntimeError(f"the viewer server did not start within {timeout:g} s")

    def stop(self, timeout: float = 10.0) -> None:
        self.server.should_exit = True
        self.thread.join(timeout)
        self.sock.close()

    def __enter__(self) -> BackgroundServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
