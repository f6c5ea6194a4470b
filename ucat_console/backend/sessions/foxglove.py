"""Foxglove well-known messages written beside our own channels.

The body pose is also written as ``foxglove.FrameTransform`` (so Foxglove's 3-D panel
places the hull) and every event as ``foxglove.Log`` (so its Log panel lists them). Both
use JSON encoding with the JSON Schemas Foxglove publishes for them (schemas/jsonschema in
the foxglove-sdk repository; the fields match the protobuf definitions of the PyPI package
``foxglove-schemas-protobuf``). The schemas below hold the fields we write.

These channels are derived: the session reader and the player skip them.
"""

from __future__ import annotations

import json
import math
from typing import Any

from ucat_console.telemetry.events import LEVELS, Event
from ucat_console.telemetry.messages import BodyState

FRAME_TRANSFORM = "foxglove.FrameTransform"
LOG = "foxglove.Log"
#: topics of the derived channels
TF_TOPIC = "foxglove/tf"
LOG_TOPIC = "foxglove/log"
#: frames of the body pose (NED world, body)
PARENT_FRAME = "ned"
CHILD_FRAME = "body"

_TIME = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
    },
}


def _xyz(names: str, title: str) -> dict[str, Any]:
    return {
        "title": title,
        "type": "object",
        "properties": {n: {"type": "number"} for n in names},
        "required": list(names),
    }


FRAME_TRANSFORM_SCHEMA: dict[str, Any] = {
    "title": FRAME_TRANSFORM,
    "description": "A transform between two reference frames in 3D space",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "parent_frame_id": {"type": "string"},
        "child_frame_id": {"type": "string"},
        "translation": _xyz("xyz", "foxglove.Vector3"),
        "rotation": _xyz("xyzw", "foxglove.Quaternion"),
    },
    "required": ["timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation"],
}

#: foxglove.LogLevel: UNKNOWN 0, DEBUG 1, INFO 2, WARNING 3, ERROR 4, FATAL 5
LOG_LEVELS = {"unknown": 0, "debug": 1, "info": 2, "warning": 3, "error": 4, "fatal": 5}
assert all(LOG_LEVELS[name] == i + 1 for i, name in enumerate(LEVELS))

LOG_SCHEMA: dict[str, Any] = {
    "title": LOG,
    "description": "A log message",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "level": {
            "title": "foxglove.LogLevel",
            "oneOf": [{"title": k.upper(), "const": v} for k, v in LOG_LEVELS.items()],
        },
        "message": {"type": "string"},
        "name": {"type": "string"},
        "file": {"type": "string"},
        "line": {"type": "integer", "minimum": 0},
    },
    "required": ["timestamp", "level", "message", "name", "file", "line"],
}

#: (topic, schema name, schema) of each derived channel
DERIVED = (
    (TF_TOPIC, FRAME_TRANSFORM, FRAME_TRANSFORM_SCHEMA),
    (LOG_TOPIC, LOG, LOG_SCHEMA),
)
SCHEMA_NAMES = {name for _, name, _ in DERIVED}


def schema_bytes(schema: dict[str, Any]) -> bytes:
    return json.dumps(schema, indent=1).encode()


def timestamp(ns: int) -> dict[str, int]:
    """foxglove time {sec, nsec} of nanoseconds since the UNIX epoch (>= 0)."""
    sec, nsec = divmod(max(0, int(ns)), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def frame_transform(state: BodyState, ns: int) -> dict[str, Any] | None:
    """The body pose as a foxglove.FrameTransform, None when the pose is not finite."""
    px, py, pz = state.position
    qw, qx, qy, qz = state.orientation
    values = (px, py, pz, qw, qx, qy, qz)
    if not all(math.isfinite(v) for v in values):
        return None
    return {
        "timestamp": timestamp(ns),
        "parent_frame_id": PARENT_FRAME,
        "child_frame_id": CHILD_FRAME,
        "translation": {"x": float(px), "y": float(py), "z": float(pz)},
        "rotation": {"x": float(qx), "y": float(qy), "z": float(qz), "w": float(qw)},
    }


def log_message(event: Event, ns: int) -> dict[str, Any]:
    """An event as a foxglove.Log: name = source, message = "code: message"."""
    return {
        "timestamp": timestamp(ns),
        "level": LOG_LEVELS.get(event.level, 0),
        "message": f"{event.code}: {event.message}",
        "name": event.source,
        "file": "",
        "line": 0,
    }


def encode(obj: dict[str, Any]) -> bytes:
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()


__all__ = [
    "CHILD_FRAME",
    "DERIVED",
    "FRAME_TRANSFORM",
    "LOG",
    "LOG_TOPIC",
    "PARENT_FRAME",
    "TF_TOPIC",
    "frame_transform",
    "log_message",
]
