"""The viewer's message schema: what is accepted, what is refused, and a fuzz test."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _viewer import sim2_session
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from formationlab.viewer import Controller
from formationlab.viewer.controller import RateLimiter
from formationlab.viewer.messages import (
    MAX_MESSAGE_BYTES,
    MessageError,
    decode_binary,
    encode_binary,
    parse_message,
)

TYPES = [
    "hello", "tick", "pause", "step", "reset", "speed", "drag", "release", "set_law",
    "set_params", "set_integrator", "perturb", "export_scenario", "seek",
]  # fmt: skip


def test_valid_messages_parse_to_their_models():
    m = parse_message('{"type": "drag", "robot": 2, "x": 0, "y": -1.5}')
    assert (type(m).__name__, m.robot, m.x, m.y) == ("Drag", 2, 0.0, -1.5)
    m = parse_message(b'{"type": "set_params", "params": {"k_a": 5}}')
    assert m.params == {"k_a": 5.0}
    assert parse_message('{"type": "step"}').count == 1


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("not json", "invalid"),
        ('{"type": "launch"}', "type"),
        ('{"type": "drag", "robot": 1, "x": 0}', "y"),
        ('{"type": "drag", "robot": 0, "x": 0, "y": 0}', "robot"),
        ('{"type": "drag", "robot": 1, "x": NaN, "y": 0}', "invalid"),
        ('{"type": "drag", "robot": 1, "x": 1e9, "y": 0}', "x"),
        ('{"type": "drag", "robot": "1", "x": 0, "y": 0}', "robot"),
        ('{"type": "tick", "extra": 1}', "extra"),
        ('{"type": "speed", "value": 0}', "value"),
        ('{"type": "set_params", "params": {"k_a": -1}}', "k_a"),
        ('{"type": "set_law", "name": "../../etc"}', "name"),
        ("[1, 2, 3]", "invalid"),
    ],
)
def test_bad_messages_are_refused_with_the_field_named(text, needle):
    with pytest.raises(MessageError, match=needle):
        parse_message(text)


def test_oversized_message_is_refused_before_parsing():
    big = json.dumps({"type": "tick", "pad": "x" * MAX_MESSAGE_BYTES})
    with pytest.raises(MessageError, match=f"{len(big)} bytes refused"):
        parse_message(big)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=20),
    lambda kids: (
        st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=10), kids, max_size=4)
    ),
    max_leaves=12,
)
messages = st.fixed_dictionaries(
    {"type": st.sampled_from(TYPES)},
    optional={
        k: json_values
        for k in ("robot", "x", "y", "paused", "count", "value", "name", "params", "dt", "scale",
                  "index")
    },
)  # fmt: skip


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(messages, json_values))
def test_fuzz_schema_accepts_or_raises_message_error(obj):
    text = json.dumps(obj)
    try:
        m = parse_message(text)
    except MessageError as exc:
        assert str(exc)
    else:
        assert m.type in TYPES and isinstance(obj, dict) and obj["type"] == m.type


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(messages)
def test_fuzz_controller_always_answers(obj):
    # a fresh session would make the test slow; one per example is still cheap for 3 robots
    ctl = Controller(sim2_session(step_budget_s=0.002))
    replies = ctl.handle(json.dumps(obj))
    assert replies and all(r.header["type"] in {"info", "frame", "error", "settings", "export"}
                           for r in replies)  # fmt: skip
    assert not any(r.header.get("code") == "internal" for r in replies), replies
    assert np.all(np.isfinite(ctl.session.q))


def test_binary_frames_round_trip():
    pos = np.arange(8, dtype="<f4")
    data = encode_binary({"type": "frame", "t": 1.5, "V": float("nan")}, [pos.tobytes()])
    header, buffers = decode_binary(data)
    assert header == {"type": "frame", "t": 1.5, "V": None}
    assert np.array_equal(np.frombuffer(buffers[0], "<f4"), pos)
    assert (data.index(buffers[0])) % 4 == 0  # float32 views need no copy


def test_rate_limiter_token_bucket():
    now = [0.0]
    lim = RateLimiter(rate=10.0, burst=5.0, clock=lambda: now[0])
    assert [lim.allow() for _ in range(7)] == [True] * 5 + [False] * 2
    now[0] = 0.3  # 3 tokens back
    assert [lim.allow() for _ in range(4)] == [True] * 3 + [False]
    assert lim.dropped == 3
    assert lim.should_warn() and not lim.should_warn()
