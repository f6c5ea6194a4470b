"""The camera's frames in a session file and on the live Foxglove server: channel
``camera/image`` written as Foxglove's well-known ``foxglove.CompressedImage`` (its official
JSON Schema, shipped in ``foxglove_schemas/``), so Foxglove's Image panel shows it.

Foxglove's JSON encoding holds a ``bytes`` field as a base64 string: ``data`` is the JPEG in
base64. The message's ``timestamp`` is the file time (nanoseconds since the UNIX epoch, as
the message's log time); ``t``, beside the schema's fields (the schema allows others), keeps
the stream time the other channels hold, which the session reader reads back.

The channel's message type carries bytes, which the derived schemas of
:mod:`~ucat_console.backend.sessions.schema` do not describe: this module is its encoding,
written by hand because no library writes a dataclass as a Foxglove well-known message."""

from __future__ import annotations

import base64
import binascii
import functools
from pathlib import Path
from typing import Any

from ucat_console.backend.sessions.codec import compact_json, loads
from ucat_console.telemetry.messages import CameraImage

SCHEMA = "foxglove.CompressedImage"
#: the message types written as a Foxglove well-known message, and its schema's name
TYPES: dict[type, str] = {CameraImage: SCHEMA}
#: the reader's encoding number for these channels (beside codec's 1 and 2)
ENCODING = 100
_FORMATS = ("jpeg", "png", "webp", "avif")


@functools.cache
def schema_bytes() -> bytes:
    return (Path(__file__).with_name("foxglove_schemas") / "CompressedImage.json").read_bytes()


def encode(msg: CameraImage, ns: int) -> bytes:
    """``msg`` as a ``foxglove.CompressedImage`` JSON message stamped ``ns`` (file time)."""
    if not isinstance(msg.data, (bytes, bytearray)):
        raise ValueError(f"CameraImage.data: expected bytes, got {type(msg.data).__name__}")
    sec, nsec = divmod(int(ns), 1_000_000_000)
    return compact_json({
        "timestamp": {"sec": max(0, sec), "nsec": nsec}, "frame_id": msg.frame_id,
        "data": base64.b64encode(msg.data).decode("ascii"), "format": msg.format, "t": msg.t,
    })


def decode(cls: type, data: bytes) -> CameraImage:
    """A ``foxglove.CompressedImage`` JSON message -> a CameraImage (ValueError naming the
    field that is wrong)."""
    obj = loads(cls, data)
    if not isinstance(obj, dict):
        raise ValueError(f"{cls.__name__}: expected a JSON object")
    t = obj.get("t")
    if isinstance(t, bool) or not isinstance(t, (int, float)):
        raise ValueError(f"{cls.__name__}.t: expected a number, got {type(t).__name__}")
    fmt, frame = obj.get("format"), obj.get("frame_id")
    if not isinstance(fmt, str) or fmt not in _FORMATS:
        raise ValueError(f"{cls.__name__}.format: expected one of {', '.join(_FORMATS)}")
    if not isinstance(frame, str):
        raise ValueError(f"{cls.__name__}.frame_id: expected a string")
    raw = obj.get("data")
    if not isinstance(raw, str):
        raise ValueError(f"{cls.__name__}.data: expected a base64 string")
    try:
        payload = base64.b64decode(raw, validate=True)
    except (binascii.Error, ValueError):
        raise ValueError(f"{cls.__name__}.data: not base64") from None
    return CameraImage(t=float(t), frame_id=frame, format=fmt, data=payload)


def is_image(cls: Any) -> bool:
    return cls in TYPES


def check_schema(topic: str, schema: Any, channel: Any, path: Any) -> int:
    """For the session reader: :data:`ENCODING` when ``topic`` is an image channel with its
    schema, 0 when it is no image channel; ValueError for an image channel with another."""
    from ucat_console.telemetry.channels import CHANNELS
    want = TYPES.get(CHANNELS.get(topic))  # type: ignore[arg-type]
    if want is None:
        return 0
    if schema is None or schema.name != want or channel.message_encoding != "json":
        raise ValueError(f"{path}: not a session file: channel {topic} is not {want} (json)")
    return ENCODING
