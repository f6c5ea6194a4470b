"""Foxglove well-known messages written beside our own channels: the robot in the 3-D panel.

A session file (and the live Foxglove server, :mod:`ucat_console.backend.foxglove_live`)
carries, besides the telemetry channels:

    foxglove/tf_static  foxglove.FrameTransform  world -> ned, once (at the first message)
    foxglove/tf         foxglove.FrameTransform  ned -> body with every body state, and
                                                 body -> fin<i> with every fin state (the
                                                 fin's mount turned by its measured angle)
    foxglove/scene      foxglove.SceneUpdate     hull, nose and fins as cubes, once
    foxglove/log        foxglove.Log             every event (name = source)

Frames: ``world`` is the z-up root a 3-D view expects (x north, y west, z up: NED turned
half a turn about north, so the water surface is the z = 0 plane and the robot is drawn
right way up below it); ``ned`` is the telemetry's world frame; ``body`` the vehicle (x
forward, y starboard, z down); ``fin<i>`` each fin's blade frame (x along the chord, z the
axis it turns about), children of ``body``. Scene entities are ``frame_locked`` in
``body`` and ``fin<i>``, so they move with the transforms.

The messages use JSON encoding with schemas that hold the fields we write, following the
JSON Schemas Foxglove publishes for them (schemas/jsonschema of the foxglove-sdk
repository, also the npm package ``@foxglove/schemas``, against which the test suite
checks every message). Every array field of a ``foxglove.SceneEntity`` is written, empty
where unused: the 3-D panel iterates all of them.

The robot's shape comes from one function, :func:`scene_update`, taking the geometry
(hull size, fin mount poses, fin length) as arguments; :func:`robot_geometry` reads it
from the plant configuration. These channels are derived: the session reader and the
player skip them.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any, Sequence

from ucat_console.backend.sessions.codec import compact_json
from ucat_console.telemetry.channels import BODY_STATE, EVENTS, N_FINS, fin_state
from ucat_console.telemetry.events import LEVELS, Event
from ucat_console.telemetry.messages import BodyState, FinState
from ucat_console.robot.geometry import BLADE_LENGTH_FACTOR, BLADE_SPAN, BLADE_THICKNESS, fin_mount
from ucat_console.robot.look import FIN_COLOURS, HULL_COLOUR, NOSE_COLOUR

FRAME_TRANSFORM = "foxglove.FrameTransform"
LOG = "foxglove.Log"
SCENE_UPDATE = "foxglove.SceneUpdate"
#: topics of the derived channels
TF_TOPIC = "foxglove/tf"
TF_STATIC_TOPIC = "foxglove/tf_static"
SCENE_TOPIC = "foxglove/scene"
LOG_TOPIC = "foxglove/log"
#: frames
WORLD_FRAME = "world"
PARENT_FRAME = "ned"
CHILD_FRAME = "body"
#: world -> ned: half a turn about x (north), (x, y, z, w)
WORLD_TO_NED = (1.0, 0.0, 0.0, 0.0)

NOSE_LENGTH = 0.03  # m

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]  # (w, x, y, z), as the telemetry holds it


def fin_frame(fin: int) -> str:
    return f"fin{fin}"


# ---------------------------------------------------------------------- schemas
def _obj(title: str, props: dict[str, Any], description: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {"title": title, "type": "object", "properties": props,
                           "required": list(props)}
    if description:
        out["description"] = description
    return out


def _numbers(names: str, title: str) -> dict[str, Any]:
    return _obj(title, {n: {"type": "number"} for n in names})


_TIME = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
    },
}
_DURATION = {
    "type": "object",
    "title": "duration",
    "properties": {
        "sec": {"type": "integer"},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
    },
}
_VECTOR3 = _numbers("xyz", "foxglove.Vector3")
_QUATERNION = _numbers("xyzw", "foxglove.Quaternion")
_POSE = _obj("foxglove.Pose", {"position": _VECTOR3, "orientation": _QUATERNION})

FRAME_TRANSFORM_SCHEMA: dict[str, Any] = {
    "title": FRAME_TRANSFORM,
    "description": "A transform between two reference frames in 3D space",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "parent_frame_id": {"type": "string"},
        "child_frame_id": {"type": "string"},
        "translation": _VECTOR3,
        "rotation": _QUATERNION,
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

_CUBE = _obj("foxglove.CubePrimitive", {
    "pose": _POSE, "size": _VECTOR3, "color": _numbers("rgba", "foxglove.Color"),
})
#: primitive kinds we never write (their arrays are always empty)
_UNUSED = ("arrows", "spheres", "cylinders", "lines", "triangles", "texts", "models")
_ENTITY = _obj("foxglove.SceneEntity", {
    "timestamp": _TIME,
    "frame_id": {"type": "string"},
    "id": {"type": "string"},
    "lifetime": _DURATION,
    "frame_locked": {"type": "boolean"},
    "metadata": {"type": "array", "items": _obj("foxglove.KeyValuePair", {
        "key": {"type": "string"}, "value": {"type": "string"}})},
    "cubes": {"type": "array", "items": _CUBE},
    **{k: {"type": "array", "maxItems": 0, "items": {"type": "object", "properties": {}}}
       for k in _UNUSED},
})
SCENE_UPDATE_SCHEMA: dict[str, Any] = {
    "title": SCENE_UPDATE,
    "description": "An update to the entities displayed in a 3D scene",
    "type": "object",
    "properties": {
        "deletions": {"type": "array", "maxItems": 0,
                      "items": {"type": "object", "properties": {}}},
        "entities": {"type": "array", "items": _ENTITY},
    },
    "required": ["deletions", "entities"],
}

#: (topic, schema name, schema) of each derived channel
DERIVED = (
    (TF_STATIC_TOPIC, FRAME_TRANSFORM, FRAME_TRANSFORM_SCHEMA),
    (TF_TOPIC, FRAME_TRANSFORM, FRAME_TRANSFORM_SCHEMA),
    (SCENE_TOPIC, SCENE_UPDATE, SCENE_UPDATE_SCHEMA),
    (LOG_TOPIC, LOG, LOG_SCHEMA),
)
DERIVED_TOPICS = {topic: name for topic, name, _ in DERIVED}


def schema_bytes(schema: dict[str, Any]) -> bytes:
    return json.dumps(schema, indent=1).encode()


encode = compact_json


# ---------------------------------------------------------------------- messages
def timestamp(ns: int) -> dict[str, int]:
    """foxglove time {sec, nsec} of nanoseconds since the UNIX epoch (>= 0)."""
    sec, nsec = divmod(max(0, int(ns)), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def _xyz(v: Sequence[float]) -> dict[str, float]:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _xyzw(q: Quat) -> dict[str, float]:
    w, x, y, z = q
    return {"x": float(x), "y": float(y), "z": float(z), "w": float(w)}


def _transform(parent: str, child: str, ns: int, translation: Sequence[float],
               rotation: Quat) -> dict[str, Any] | None:
    """A foxglove.FrameTransform; None when a number of it is not finite. (The recorder
    makes one with every body state and fin state: written out, without loops.)"""
    isfinite = math.isfinite
    x, y, z = translation
    qw, qx, qy, qz = rotation
    if not (isfinite(x) and isfinite(y) and isfinite(z) and isfinite(qw) and isfinite(qx) and isfinite(qy)
            and isfinite(qz)):
        return None
    sec, nsec = divmod(max(0, int(ns)), 1_000_000_000)
    return {
        "timestamp": {"sec": sec, "nsec": nsec},
        "parent_frame_id": parent,
        "child_frame_id": child,
        "translation": {"x": float(x), "y": float(y), "z": float(z)},
        "rotation": {"x": float(qx), "y": float(qy), "z": float(qz), "w": float(qw)},
    }


def frame_transform(state: BodyState, ns: int) -> dict[str, Any] | None:
    """The body pose as a foxglove.FrameTransform ned -> body, None when it is not finite."""
    return _transform(PARENT_FRAME, CHILD_FRAME, ns, state.position, state.orientation)


def world_transform(ns: int) -> dict[str, Any]:
    """The static transform world (z up) -> ned."""
    x, y, z, w = WORLD_TO_NED
    out = _transform(WORLD_FRAME, PARENT_FRAME, ns, (0.0, 0.0, 0.0), (w, x, y, z))
    assert out is not None
    return out


def fin_transform(state: FinState, mount: tuple[Vec3, Quat], ns: int) -> dict[str, Any] | None:
    """body -> fin<i>: the fin's mount turned about its z axis by the measured angle
    (None when the angle is not finite)."""
    position, (aw, ax, ay, az) = mount
    angle = state.angle
    if not math.isfinite(angle):  # (math.cos refuses an infinite one)
        return None
    half = angle / 2
    bw, bz = math.cos(half), math.sin(half)
    # the mount's orientation times (cos, 0, 0, sin): a turn about the mount's z axis
    turned = (aw * bw - az * bz, ax * bw + ay * bz, ay * bw - ax * bz, aw * bz + az * bw)
    return _transform(CHILD_FRAME, fin_frame(state.fin), ns, position, turned)


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


def _cube(position: Vec3, size: Vec3, rgb: tuple[int, int, int]) -> dict[str, Any]:
    r, g, b = (c / 255 for c in rgb)  # the console's view's colours, 0-255
    return {
        "pose": {"position": _xyz(position), "orientation": _xyzw((1.0, 0.0, 0.0, 0.0))},
        "size": _xyz(size),
        "color": {"r": r, "g": g, "b": b, "a": 1.0},
    }


def _entity(ns: int, frame: str, eid: str, cubes: list[dict[str, Any]]) -> dict[str, Any]:
    return {
        "timestamp": timestamp(ns),
        "frame_id": frame,
        "id": eid,
        "lifetime": {"sec": 0, "nsec": 0},  # until replaced
        "frame_locked": True,
        "metadata": [],
        "cubes": cubes,
        **{k: [] for k in _UNUSED},
    }


def scene_update(hull_size: Vec3, fin_mounts: Sequence[tuple[Vec3, Quat]], fin_length: float,
                 ns: int) -> dict[str, Any]:
    """The robot as a foxglove.SceneUpdate: the hull (a box of ``hull_size`` length, width,
    height, with a red nose at the front) in ``body``, and each fin's blade (``fin_length``
    along its chord) in ``fin<i>``. ``fin_mounts`` are the fins' mount poses in the body
    frame (position, orientation (w, x, y, z) of the axes x_m, y_m, normal), by fin index;
    they also place the fin frames (:func:`fin_transform`)."""
    length, width, height = hull_size
    entities = [_entity(ns, CHILD_FRAME, "hull", [
        _cube((0.0, 0.0, 0.0), hull_size, HULL_COLOUR),
        _cube((length / 2 + NOSE_LENGTH / 2, 0.0, 0.0),
              (NOSE_LENGTH, width * 0.6, height * 0.6), NOSE_COLOUR),
    ])]
    for i in range(len(fin_mounts)):
        entities.append(_entity(ns, fin_frame(i), f"fin{i}", [
            _cube((fin_length / 2, 0.0, 0.0), (fin_length, BLADE_THICKNESS, BLADE_SPAN),
                  FIN_COLOURS[i % len(FIN_COLOURS)]),
        ]))
    return {"deletions": [], "entities": entities}


@dataclass(frozen=True)
class RobotGeometry:
    """What the 3-D scene draws: hull size, fin mount poses (body frame) and fin length."""

    hull_size: Vec3
    fin_mounts: tuple[tuple[Vec3, Quat], ...]
    fin_length: float


def robot_geometry(plant: Any = None) -> RobotGeometry:
    """The geometry of the plant configuration (``PlantConfig``; default: its defaults), as
    the console's own 3-D view draws it (``ui/scene.py``: fin mounts, sizes, colours)."""
    from ucat_console.backend.sim.params import PlantConfig

    g = (plant if plant is not None else PlantConfig()).geometry
    size = tuple(float(x) for x in g.hull_size)
    mounts = tuple(fin_mount(g, i) for i in range(N_FINS))
    return RobotGeometry(size, mounts, BLADE_LENGTH_FACTOR * g.fin_length)  # type: ignore[arg-type]


class Derived:
    """The derived channels' messages for one robot geometry (the recorder's and the live
    server's one source of them)."""

    def __init__(self, geometry: RobotGeometry) -> None:
        self.geometry = geometry
        self._fin_channels = {fin_state(i): i for i in range(len(geometry.fin_mounts))}

    def opening(self, ns: int) -> list[tuple[str, bytes]]:
        """The static transform and the scene, written once before the first message."""
        g = self.geometry
        return [
            (TF_STATIC_TOPIC, encode(world_transform(ns))),
            (SCENE_TOPIC, encode(scene_update(g.hull_size, g.fin_mounts, g.fin_length, ns))),
        ]

    def derive(self, channel: str, msg: Any, ns: int) -> list[tuple[str, bytes]]:
        """The derived messages of one telemetry message (none for most channels)."""
        if channel == BODY_STATE:
            tf = frame_transform(msg, ns)
            return [] if tf is None else [(TF_TOPIC, encode(tf))]
        if channel == EVENTS:
            return [(LOG_TOPIC, encode(log_message(msg, ns)))]
        fin = self._fin_channels.get(channel)
        if fin is not None:
            tf = fin_transform(msg, self.geometry.fin_mounts[fin], ns)
            return [] if tf is None else [(TF_TOPIC, encode(tf))]
        return []
