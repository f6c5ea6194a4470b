"""JSON Schemas of the telemetry messages, derived from each dataclass's type hints.

Every channel of a session file carries JSON messages (MCAP message encoding ``json``)
described by a JSON Schema (schema encoding ``jsonschema``, dialect 2020-12), so that
Foxglove/Lichtblick and PlotJuggler show every channel. Each field's ``description`` is
its :class:`~ucat_console.robot.fields.Doc` (meaning, unit, frame).

Type mapping (the only kinds a message field may have), encoding 2:

    float                    {"type": "number"}, not required (see non-finite below)
    int / bool / str         {"type": "integer" | "boolean" | "string"}
    int, Doc(wide=True)      {"type": "string", "pattern": "^-?[0-9]+$"}: an integer that may
                             exceed 2^53 (a planner seed), which JavaScript and PlotJuggler
                             would round as a number
    tuple[float, ...n...]    with Doc names: an object of n numbers keyed by the names
                             (``position.x``; a quaternion held (w, x, y, z) is written
                             {x, y, z, w}, as foxglove.Quaternion); without names (per-fin
                             values): a fixed-length array, "prefixItems" of n
                             {"type": ["number", "null"]}, "minItems" = "maxItems" = n, and
                             "items": {"type": "number"}
    tuple[X, ...]            variable-length array of X in int / bool / str
    dict[str, Any]           {"type": "object"} with any JSON values
    X | None                 X's schema, the key left out when the value is None

Units. Every number with a unit carries it machine-readably in a ``unit`` keyword beside
its ``type`` (one per vector part: ``position.x``, ``per_fin[2]``, ``u.w_1``): an SI
symbol a units library parses (``m/s``, ``m/s^2``, ``rad/s``, ``N m``; ``1`` for a
dimensionless number).
JSON Schema 2020-12 keeps an unknown keyword as an annotation, so validators and Foxglove
read the schemas as before (a validator in a strict mode, like ajv's default, is told about
the keyword: ``ajv.addKeyword("unit")``).

Non-finite numbers. JSON has no NaN or infinity, and Foxglove's and Lichtblick's schema
reader takes one type name per field (a ``"type": ["number", "null"]`` field makes it
reject the whole channel), so a number field cannot also hold null. A non-finite float is
therefore written as no value (the key left out of its object; ``null`` inside an array,
whose elements are described positionally by ``prefixItems``, which a 2020-12 validator
applies, while ``items``, all Foxglove reads, covers none of them) and the message's
``nonfinite`` object names it by its path with what it was:
``{"depth": "nan", "rates.z": "-inf", "per_fin[2]": "nan"}``. Foxglove and PlotJuggler
show a gap; the decoder puts the value back. Inside ``Event.data`` (free-form JSON) a
non-finite number becomes ``null``.

Files written before encoding 2 (schemas without ``$id``) held every tuple as an array,
wrote +/-inf as ``1e999`` and a NaN scalar as a missing key, and the seed as a number;
:mod:`ucat_console.backend.sessions.legacy` reads them.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import types
import typing
from dataclasses import dataclass
from typing import Any

from ucat_console.robot.fields import WXYZ, XYZ, Doc, field_docs

#: MCAP encodings of our channels
SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"
#: JSON Schema dialect of every schema written
DIALECT = "https://json-schema.org/draft/2020-12/schema"
#: prefix of our schema names: "ucat_console.<class name>"
SCHEMA_PREFIX = "ucat_console."
#: the encoding written now; a schema's ``$id`` names it: ``urn:ucat-console:telemetry:2:<class>``
ENCODING = 2
ID_PREFIX = f"urn:ucat-console:telemetry:{ENCODING}:"
#: the field listing a message's non-finite numbers, and what each was
NONFINITE = "nonfinite"
NONFINITE_VALUES = {"nan": float("nan"), "inf": float("inf"), "-inf": float("-inf")}
WIDE_PATTERN = "^-?[0-9]+$"

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

NOTE = (
    "ucat_console encoding 2. A non-finite number is written as no value (key left out; "
    "null inside an array) and listed in 'nonfinite' by its path (nan, inf or -inf)."
)


@dataclass(frozen=True)
class FieldSpec:
    """One message field as the codec and the schema see it."""

    name: str
    kind: str
    optional: bool = False  # ``X | None``: None is written by leaving the key out
    length: int = 0  # FLOATS: the fixed length
    item: str = ""  # SEQ: the element kind
    doc: Doc | None = None

    @property
    def names(self) -> tuple[str, ...]:
        """FLOATS written as an object: its keys in tuple order (empty: an array)."""
        return self.doc.names if self.doc is not None else ()

    @property
    def wide(self) -> bool:
        """INT written as a decimal string."""
        return self.doc is not None and self.doc.wide

    def paths(self) -> list[str]:
        """MCAP-style paths of the field's numbers: ``depth``, ``position.x``, ``per_fin[2]``
        (for other kinds, the field's name)."""
        if self.kind != FLOATS:
            return [self.name]
        if self.names:
            return [f"{self.name}.{n}" for n in self.names]
        return [f"{self.name}[{i}]" for i in range(self.length)]


def _unwrap_optional(tp: Any) -> tuple[Any, bool]:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(tp)) == 2:
            return args[0], True
    return tp, False


def _spec(cls: type, name: str, tp: Any, doc: Doc | None) -> FieldSpec:
    where = f"{cls.__name__}.{name}"
    if name == NONFINITE:
        raise TypeError(f"{where}: the name {NONFINITE!r} is the codec's")
    inner, optional = _unwrap_optional(tp)
    if doc is not None and doc.wide and inner is not int:
        raise TypeError(f"{where}: only an int can be wide")
    if inner in _SCALARS:
        kind = _SCALARS[inner]
        if optional and kind == FLOAT:
            raise TypeError(f"{where}: float | None is not supported (None and NaN would collide)")
        return FieldSpec(name, kind, optional, doc=doc)
    origin = typing.get_origin(inner)
    args = typing.get_args(inner)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            item = _SCALARS.get(args[0])
            if item in (INT, BOOL, STR):
                return FieldSpec(name, SEQ, optional, item=item, doc=doc)
            raise TypeError(f"{where}: variable-length tuples of {args[0]!r} are not supported")
        if args and all(a is float for a in args):
            if doc is not None and doc.names and len(doc.names) != len(args):
                raise TypeError(f"{where}: {len(doc.names)} names for {len(args)} values")
            return FieldSpec(name, FLOATS, optional, length=len(args), doc=doc)
        raise TypeError(f"{where}: only fixed-length tuples of floats are supported, got {inner!r}")
    if origin is dict and args and args[0] is str:
        return FieldSpec(name, JSON, optional, doc=doc)
    raise TypeError(f"{where}: unsupported field type {tp!r}")


@functools.cache
def field_specs(cls: type) -> tuple[FieldSpec, ...]:
    """The fields of message dataclass ``cls`` (TypeError for an unsupported field type)."""
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    hints = typing.get_type_hints(cls)
    docs = field_docs(cls)
    return tuple(_spec(cls, f.name, hints[f.name], docs.get(f.name))
                 for f in dataclasses.fields(cls))


def schema_name(cls: type) -> str:
    return SCHEMA_PREFIX + cls.__name__


#: the keyword of a number's unit
UNIT = "unit"


def _with_unit(schema: dict[str, Any], unit: str) -> dict[str, Any]:
    return {**schema, UNIT: unit} if unit else schema


def _field_schema(spec: FieldSpec) -> dict[str, Any]:
    out: dict[str, Any]
    units = spec.doc.units(spec.length or 1) if spec.doc is not None else ("",) * (spec.length or 1)
    if spec.kind == INT and spec.wide:
        out = {"type": "string", "pattern": WIDE_PATTERN}
    elif spec.kind in (FLOAT, INT):
        out = _with_unit({"type": _JSON_TYPES[spec.kind]}, units[0])
    elif spec.kind in _JSON_TYPES:
        out = {"type": _JSON_TYPES[spec.kind]}
    elif spec.kind == FLOATS and spec.names:
        unit_of = dict(zip(spec.names, units))
        out = {
            "type": "object",
            "properties": {n: _with_unit({"type": "number"}, unit_of[n]) for n in _object_order(spec.names)},
            "additionalProperties": False,
        }
        if spec.names == WXYZ:
            out["title"] = "foxglove.Quaternion"
        elif spec.names == XYZ:
            out["title"] = "foxglove.Vector3"
    elif spec.kind == FLOATS:
        n = spec.length
        out = {
            "type": "array",
            "minItems": n,
            "maxItems": n,
            "prefixItems": [_with_unit({"type": ["number", "null"]}, u) for u in units],
            "items": {"type": "number"},
        }
    elif spec.kind == SEQ:
        out = {"type": "array", "items": {"type": _JSON_TYPES[spec.item]}}
    elif spec.kind == JSON:
        out = {"type": "object", "properties": {}, "additionalProperties": True}
    else:
        raise AssertionError(spec.kind)
    if spec.doc is not None:
        text = spec.doc.describe()
        if spec.kind == INT and spec.wide:
            text += "; an integer written as a decimal string (it may exceed 2^53)"
        elif spec.kind == FLOATS and not spec.names:
            text += "; fixed length, null for a non-finite value (see nonfinite)"
        out["description"] = text
    return out


def _object_order(names: tuple[str, ...]) -> tuple[str, ...]:
    """Keys in the order tools expect: a quaternion x, y, z, w."""
    return ("x", "y", "z", "w") if names == WXYZ else names


_NONFINITE_SCHEMA = {
    "type": "object",
    "description": "the message's non-finite numbers, by path (depth, position.x, per_fin[2]): "
                   "nan, inf or -inf; those values are left out of the message",
    "properties": {},
    "additionalProperties": {"type": "string", "enum": list(NONFINITE_VALUES)},
}


@functools.cache
def _json_schema(cls: type) -> str:
    specs = field_specs(cls)
    props = {s.name: _field_schema(s) for s in specs}
    props[NONFINITE] = _NONFINITE_SCHEMA
    schema = {
        "$schema": DIALECT,
        "$id": ID_PREFIX + cls.__name__,
        "title": schema_name(cls),
        "description": (cls.__doc__ or cls.__name__).strip().splitlines()[0],
        "$comment": NOTE,
        "type": "object",
        "properties": props,
        "required": [s.name for s in specs if not s.optional and s.kind != FLOAT],
        "additionalProperties": False,
    }
    return json.dumps(schema, indent=1)


def json_schema(cls: type) -> dict[str, Any]:
    """The JSON Schema (a fresh dict) of message dataclass ``cls``."""
    return json.loads(_json_schema(cls))


def json_schema_bytes(cls: type) -> bytes:
    """The schema as stored in a session file."""
    return _json_schema(cls).encode()


def schema_encoding(schema: dict[str, Any]) -> int:
    """The encoding a stored schema describes: 2 for ``$id`` ``urn:ucat-console:telemetry:2:...``,
    1 for a file written before (no ``$id``); ValueError for another."""
    sid = schema.get("$id")
    if sid is None:
        return 1
    if isinstance(sid, str) and sid.startswith(ID_PREFIX):
        return ENCODING
    raise ValueError(f"schema $id {sid!r}: not an encoding this version reads "
                     f"(expected {ID_PREFIX}<message>)")
