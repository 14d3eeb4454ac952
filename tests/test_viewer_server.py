"""The viewer's server: token, bad and huge messages, floods; it keeps running and answering."""

from __future__ import annotations

import json
import time

import httpx
import numpy as np
import pytest
from _viewer import serving, sim2_session
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from formationlab.viewer.messages import decode_binary


def _recv(ws, timeout=10.0):
    data = ws.recv(timeout=timeout)
    if isinstance(data, bytes):
        return decode_binary(data)
    return json.loads(data), []


def _until(ws, kind, limit=5000):
    """Read messages until one of type ``kind`` (bounded)."""
    seen = []
    for _ in range(limit):
        msg, bufs = _recv(ws)
        seen.append(msg["type"])
        if msg["type"] == kind:
            return msg, bufs
    pytest.fail(f"no {kind!r} among {len(seen)} messages: {seen[-5:]}")


def _hello_answered(ws, within=60.0):
    """Send hello every half second until an info reply comes (bounded by ``within`` s)."""
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        ws.send(json.dumps({"type": "hello"}))
        try:
            while True:
                msg, _ = _recv(ws, timeout=0.5)
                if msg["type"] == "info":
                    return msg
        except TimeoutError:
            continue
    pytest.fail(f"no info reply to hello within {within:g} s after the flood")


def _answers(srv):
    """A new connection gets info and a frame: the server is up and answering."""
    with connect(srv.ws_url, max_size=None) as ws:
        ws.send(json.dumps({"type": "hello"}))
        info, _ = _recv(ws)
        frame, bufs = _recv(ws)
        return info["type"] == "info" and frame["type"] == "frame" and len(bufs[0]) == 24


@pytest.fixture
def srv():
    with serving(sim2_session()) as s:
        yield s


def test_page_needs_the_token(srv):
    base = f"http://{srv.host}:{srv.port}"
    assert httpx.get(f"{base}/?token=wrong").status_code == 403
    assert httpx.get(f"{base}/").status_code == 403
    ok = httpx.get(srv.url)
    assert ok.status_code == 200 and "page.js" in ok.text
    assert "default-src 'self'" in ok.headers["content-security-policy"]
    js = httpx.get(f"{base}/app.js")
    assert js.status_code == 200 and "export default { render }" in js.text


def test_websocket_refuses_a_wrong_token(srv):
    for url in (srv.ws_url.replace(srv.token, "x" + srv.token), srv.ws_url.split("?")[0]):
        with pytest.raises(InvalidStatus) as exc:
            connect(url)
        assert exc.value.response.status_code == 403
    assert _answers(srv)


def test_malformed_message_gets_an_error_and_the_connection_lives(srv):
    with connect(srv.ws_url) as ws:
        for bad in ("{not json", '{"type": "drag", "robot": 1}', b"\x00\xff binary", "[]"):
            ws.send(bad)
            msg, _ = _recv(ws)
            assert msg["type"] == "error" and msg["code"] == "bad-message", msg
        ws.send(json.dumps({"type": "step", "count": 5}))
        frame, _ = _until(ws, "frame")
        assert frame["steps"] == 5
    assert srv.controller.session.steps == 5


def test_ten_megabyte_message_is_refused_with_an_error(srv):
    with connect(srv.ws_url, max_size=None) as ws:
        ws.send(json.dumps({"type": "tick", "pad": "x" * (10 * 1024 * 1024)}))
        msg, _ = _recv(ws, timeout=30)
        assert msg["type"] == "error" and "bytes refused" in msg["message"]
        ws.send(json.dumps({"type": "tick"}))
        assert _until(ws, "frame")[0]["type"] == "frame"


def test_message_beyond_the_transport_limit_closes_only_that_connection(srv):
    with connect(srv.ws_url, max_size=None) as ws:
        ws.send("x" * (20 * 1024 * 1024))
        with pytest.raises(ConnectionClosed) as exc:
            for _ in range(10):
                ws.recv(timeout=30)
        assert exc.value.rcvd is not None and exc.value.rcvd.code == 1009  # message too big
    assert _answers(srv)


def test_a_flood_is_rate_limited_and_the_server_keeps_answering(srv):
    with connect(srv.ws_url, max_size=None) as ws:
        for _ in range(3000):
            ws.send('{"type": "reset"}')
        ws.send(json.dumps({"type": "step", "count": 7}))
        msg, _ = _until(ws, "error")
        assert msg["code"] == "rate-limited" and "dropped" in msg["message"]
        # After the flood: still answering on this connection. The server may still be
        # working through the backlog (on a loaded machine), and a hello that arrives while
        # the bucket is empty is dropped like any other message, so ask again until answered.
        assert _hello_answered(ws)["n"] == 3
    assert _answers(srv)
    assert np.all(np.isfinite(srv.controller.session.q))


def test_drag_over_the_socket_moves_robot_on_the_server(srv):
    with connect(srv.ws_url) as ws:
        ws.send(json.dumps({"type": "pause", "paused": True}))
        _until(ws, "frame")
        ws.send(json.dumps({"type": "drag", "robot": 1, "x": -2.0, "y": -1.0}))
        frame, bufs = _until(ws, "frame")
        assert frame["pinned"] == 1
        np.testing.assert_array_equal(np.frombuffer(bufs[0], "<f4")[:2], [-2.0, -1.0])
    np.testing.assert_array_equal(srv.controller.session.q[0], [-2.0, -1.0])


def test_websocket_refuses_a_page_of_another_site(srv):
    """A browser sends the page's Origin: the viewer's own page is let in, another site's
    page is not, even with the token (cross-site websocket hijacking)."""
    own = f"http://{srv.host}:{srv.port}"
    with connect(srv.ws_url, origin=own) as ws:
        ws.send(json.dumps({"type": "hello"}))
        info, _ = _recv(ws)
        assert info["type"] == "info"
    for other in ("http://evil.example", f"http://{srv.host}:{srv.port + 1}", "null"):
        with pytest.raises(InvalidStatus) as exc:
            connect(srv.ws_url, origin=other)
        assert exc.value.response.status_code == 403
    assert _answers(srv)
