"""JSON Schemas of the telemetry messages, derived from each dataclass's type hints.

Every channel of a session file carries JSON messages (MCAP message encoding ``json``)
described by a JSON Schema (schema encoding ``jsonschema``, dialect 2020-12), so that
Foxglove/Lichtblick and PlotJuggler show every channel.

Type mapping (the only kinds a message field may have):

    float                    {"type": "number"}, not required (see NaN below)
    int / bool / str         {"type": "integer" | "boolean" | "string"}
    tuple[float, ...n...]    fixed-length array: "prefixItems" of n {"type": ["number", "null"]},
                             "minItems" = "maxItems" = n, and "items": {"type": "number"}
    tuple[X, ...]            variable-length array of X in int / bool / str
    dict[str, Any]           {"type": "object"} with any JSON values
    X | None                 X's schema, the key left out when the value is None

NaN. JSON has no NaN, and Foxglove's schema reader accepts one type name per field (a
``"type": ["number", "null"]`` field makes it reject the whole channel). So:

- a scalar float that is NaN is left out of the message (floats are never "required");
  Foxglove and PlotJuggler show a gap, and the decoder reads a missing float back as NaN;
- a NaN inside a fixed-length float array is ``null``. The array's elements are
  described positionally by ``prefixItems`` (number or null), which a 2020-12 validator
  applies; ``items`` (a plain number, all Foxglove reads) covers only elements past the
  fixed length, of which there are none;
- +/-inf are written as the JSON numbers ``1e999`` / ``-1e999`` (valid JSON grammar; they
  parse back to +/-inf in Python and JavaScript);
- inside ``Event.data`` (free-form JSON) a non-finite number becomes ``null``.
"""

from __future__ import annotations

import dataclasses
import functools
import types
import typing
from dataclasses import dataclass
from typing import Any

#: MCAP encodings of our channels
SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"
#: JSON Schema dialect of every schema written
DIALECT = "https://json-schema.org/draft/2020-12/schema"
#: prefix of our schema names: "ucat_console.<class name>"
SCHEMA_PREFIX = "ucat_console."

# field kinds
FLOAT = "float"
INT = "int"
BOOL = "bool"
STR = "str"
FLOATS = "floats"  # fixed-length tuple of floats
SEQ = "seq"  # variable-length tuple of int / bool / str
JSON = "json"  # dict[str, Any]

_SCALARS: dict[Any, str] = {float: FLOAT, int: INT, bool: BOOL, str: STR}
_JSON_TYPES = {FLOAT: "number", INT: "integer", BOOL: "boolean", STR: "string"}

NAN_NOTE = (
    "NaN: a scalar float that is NaN is left out; inside a fixed-length array it is null; "
    "+/-inf are written as 1e999 / -1e999."
)


@dataclass(frozen=True)
class FieldSpec:
    """One message field as the codec and the schema see it."""

    name: str
    kind: str
    optional: bool = False  # ``X | None``: None is written by leaving the key out
    length: int = 0  # FLOATS: the fixed length
    item: str = ""  # SEQ: the element kind


def _unwrap_optional(tp: Any) -> tuple[Any, bool]:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(tp)) == 2:
            return args[0], True
    return tp, False


def _spec(cls: type, name: str, tp: Any) -> FieldSpec:
    where = f"{cls.__name__}.{name}"
    inner, optional = _unwrap_optional(tp)
    if inner in _SCALARS:
        kind = _SCALARS[inner]
        if optional and kind == FLOAT:
            raise TypeError(f"{where}: float | None is not supported (None and NaN would collide)")
        return FieldSpec(name, kind, optional)
    origin = typing.get_origin(inner)
    args = typing.get_args(inner)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            item = _SCALARS.get(args[0])
            if item in (INT, BOOL, STR):
                return FieldSpec(name, SEQ, optional, item=item)
            raise TypeError(f"{where}: variable-length tuples of {args[0]!r} are not supported")
        if args and all(a is float for a in args):
            return FieldSpec(name, FLOATS, optional, length=len(args))
        raise TypeError(f"{where}: only fixed-length tuples of floats are supported, got {inner!r}")
    if origin is dict and args and args[0] is str:
        return FieldSpec(name, JSON, optional)
    raise TypeError(f"{where}: unsupported field type {tp!r}")


@functools.cache
def field_specs(cls: type) -> tuple[FieldSpec, ...]:
    """The fields of message dataclass ``cls`` (TypeError for an unsupported field type)."""
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    hints = typing.get_type_hints(cls)
    return tuple(_spec(cls, f.name, hints[f.name]) for f in dataclasses.fields(cls))


def schema_name(cls: type) -> str:
    return SCHEMA_PREFIX + cls.__name__


def _field_schema(spec: FieldSpec) -> dict[str, Any]:
    if spec.kind in _JSON_TYPES:
        return {"type": _JSON_TYPES[spec.kind]}
    if spec.kind == FLOATS:
        n = spec.length
        return {
            "type": "array",
            "minItems": n,
            "maxItems": n,
            "prefixItems": [{"type": ["number", "null"]} for _ in range(n)],
            "items": {"type": "number"},
            "description": "fixed length; null stands for NaN",
        }
    if spec.kind == SEQ:
        return {"type": "array", "items": {"type": _JSON_TYPES[spec.item]}}
    if spec.kind == JSON:
        return {"type": "object", "properties": {}, "additionalProperties": True}
    raise AssertionError(spec.kind)


@functools.cache
def _json_schema(cls: type) -> str:
    import json

    specs = field_specs(cls)
    schema = {
        "$schema": DIALECT,
        "title": schema_name(cls),
        "description": (cls.__doc__ or cls.__name__).strip().splitlines()[0],
        "$comment": NAN_NOTE,
        "type": "object",
        "properties": {s.name: _field_schema(s) for s in specs},
        "required": [s.name for s in specs if not s.optional and s.kind != FLOAT],
        "additionalProperties": False,
    }
    return json.dumps(schema, indent=1)


def json_schema(cls: type) -> dict[str, Any]:
    """The JSON Schema (a fresh dict) of message dataclass ``cls``."""
    import json

    return json.loads(_json_schema(cls))


def json_schema_bytes(cls: type) -> bytes:
    """The schema as stored in a session file."""
    return _json_schema(cls).encode()
