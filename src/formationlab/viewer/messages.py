"""The viewer's protocol: what the page may send (validated with pydantic) and how frames travel.

Page -> server: one JSON object per message, ``{"type": ..., ...}``, one of the
models below (unknown keys, wrong types, non-finite numbers and values out of
range are refused). A message longer than :data:`MAX_MESSAGE_BYTES` is refused
before it is parsed. Robot numbers are 1-based.

Server -> page: JSON objects (``info``, ``error``, ``notice``, ``export``) and
frames. A frame is a JSON header plus binary buffers (positions as float32,
``x0 y0 x1 y1 ...`` in the plane, ``x0 y0 z0 x1 y1 z1 ...`` in space, where ``info``
says ``dim = 3``; headings, when the model has them, as a second buffer).
``info`` describes the closed loop once (:func:`formationlab.viewer.frames.scene_info`:
``obstacles`` as circles ``{kind, center, radius}`` and polygons ``{kind, vertices}``,
``safety`` (the filter's name or null), ``marching``, ``model``, ``state_names``,
``sensing``, ``faults``); a frame's header carries, besides ``t``, ``V``, the errors and
the ``active`` surfaces, ``filtered`` (the 1-based robots whose command the safety filter
changed, null without a filter), ``filter_status`` and ``reference`` (the marching
reference velocity ``[vx, vy]``, ``[vx, vy, vz]`` in space, or null)
(:func:`formationlab.viewer.frames.live_header`).
On a websocket both go in one binary message, see :func:`encode_binary`; in the
notebook widget the buffers are the widget message's own buffers.
"""

from __future__ import annotations

import json
import math
import struct
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

from ..errors import UserInputError

__all__ = [
    "MAX_MESSAGE_BYTES",
    "Message",
    "MessageError",
    "decode_binary",
    "encode_binary",
    "parse_message",
]

#: Longest message the page may send, bytes (the longest real one is well under 1 KiB).
MAX_MESSAGE_BYTES = 64 * 1024
#: Coordinates beyond this are refused (a robot dragged a kilometre off is a mistake).
COORD_MAX = 1e6

Coord = Annotated[float, Field(ge=-COORD_MAX, le=COORD_MAX, allow_inf_nan=False)]
Gain = Annotated[float, Field(ge=0, le=1e6, allow_inf_nan=False)]
Name = Annotated[str, Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$")]


class _Msg(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class Hello(_Msg):
    """The page is ready: answer with ``info`` and a frame."""

    type: Literal["hello"]


class Tick(_Msg):
    """The page drew the last frame and wants the next one (it sends one per display frame)."""

    type: Literal["tick"]


class Pause(_Msg):
    type: Literal["pause"]
    paused: bool


class Step(_Msg):
    type: Literal["step"]
    count: int = Field(default=1, ge=1, le=10_000)


class Reset(_Msg):
    type: Literal["reset"]


class Speed(_Msg):
    """Simulated seconds per wall-clock second."""

    type: Literal["speed"]
    value: float = Field(ge=1e-3, le=1e3, allow_inf_nan=False)


class Drag(_Msg):
    """Hold robot ``robot`` (1-based) at ``(x, y)`` (in the plane) or ``(x, y, z)`` (a
    formation in space; without ``z`` the robot keeps its height) until ``release``."""

    type: Literal["drag"]
    robot: int = Field(ge=1, le=10_000_000)
    x: Coord
    y: Coord
    z: Coord | None = None


class Release(_Msg):
    type: Literal["release"]


class SetLaw(_Msg):
    type: Literal["set_law"]
    name: Name
    params: dict[Name, Gain] = Field(default_factory=dict, max_length=16)


class SetParams(_Msg):
    """Change gains of the current law, e.g. ``{"k_a": 5.0}``."""

    type: Literal["set_params"]
    params: dict[Name, Gain] = Field(max_length=16)


class SetIntegrator(_Msg):
    type: Literal["set_integrator"]
    name: Name
    dt: float = Field(gt=0, le=1.0, allow_inf_nan=False)


class Perturb(_Msg):
    """Move every robot by a random Gaussian displacement of standard deviation ``scale``."""

    type: Literal["perturb"]
    scale: float = Field(gt=0, le=100.0, allow_inf_nan=False)


class ExportScenario(_Msg):
    type: Literal["export_scenario"]


class Seek(_Msg):
    """Replay: show frame ``index`` (0-based position on the time slider)."""

    type: Literal["seek"]
    index: int = Field(ge=0, le=1_000_000_000)


Message = Annotated[
    Hello
    | Tick
    | Pause
    | Step
    | Reset
    | Speed
    | Drag
    | Release
    | SetLaw
    | SetParams
    | SetIntegrator
    | Perturb
    | ExportScenario
    | Seek,
    Field(discriminator="type"),
]
_ADAPTER: TypeAdapter[Any] = TypeAdapter(Message)


class MessageError(UserInputError):
    """A message from the page that is not one of the protocol's."""


def parse_message(data: str | bytes) -> Any:
    """Validate one message from the page.

    Parameters
    ----------
    data : str or bytes
        The message as received (JSON).

    Returns
    -------
    One of the message models (``Tick``, ``Drag``, ...).

    Raises
    ------
    MessageError
        Too long, not JSON, or not a valid message; the text says which field and why.
    """
    size = len(data.encode("utf-8")) if isinstance(data, str) else len(data)
    if size > MAX_MESSAGE_BYTES:
        raise MessageError(
            f"message of {size} bytes refused: at most {MAX_MESSAGE_BYTES} bytes are accepted"
        )
    try:
        return _ADAPTER.validate_json(data)
    except ValidationError as exc:
        raise MessageError(_describe(exc)) from None


def _describe(exc: ValidationError) -> str:
    parts = []
    for err in exc.errors(include_url=False)[:3]:
        loc = ".".join(str(x) for x in err["loc"])
        parts.append(f"{loc}: {err['msg']}" if loc else str(err["msg"]))
    more = exc.error_count() - len(parts)
    tail = f" (and {more} more)" if more > 0 else ""
    return "invalid message: " + "; ".join(parts) + tail


def _json_default(obj: Any) -> Any:
    raise TypeError(f"not JSON: {type(obj).__name__}")


def dumps(header: dict[str, Any]) -> str:
    """JSON text of a server message (NaN and infinities become null)."""
    return json.dumps(_clean(header), default=_json_default, allow_nan=False)


def _clean(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    return obj


def encode_binary(header: dict[str, Any], buffers: list[bytes]) -> bytes:
    """One websocket message holding a JSON header and binary buffers.

    Layout: ``uint32`` (little-endian) length ``H`` of the header, ``H`` bytes of
    UTF-8 JSON (with ``"buffers"``: the byte length of each buffer), zero padding
    to a multiple of 4, then the buffers one after the other (each a multiple of
    4 bytes long, so float32 views need no copy).
    """
    head = dumps({**header, "buffers": [len(b) for b in buffers]}).encode("utf-8")
    pad = (-(4 + len(head))) % 4
    return b"".join([struct.pack("<I", len(head)), head, b" " * pad, *buffers])


def decode_binary(data: bytes) -> tuple[dict[str, Any], list[bytes]]:
    """Inverse of :func:`encode_binary` (used by the tests and the benchmark)."""
    (h,) = struct.unpack_from("<I", data, 0)
    header = json.loads(data[4 : 4 + h].decode("utf-8"))
    off = 4 + h + (-(4 + h)) % 4
    buffers = []
    for nb in header.pop("buffers"):
        buffers.append(data[off : off + nb])
        off += nb
    return header, buffers
