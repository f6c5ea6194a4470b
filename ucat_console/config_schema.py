"""A JSON Schema (draft 2020-12) of the configuration, made from the fields' own metadata.

Every value of the configuration is a field declared with :func:`typedconf.param` (its
range or choices, unit and description); :func:`schema_of` walks a config dataclass and
writes the same facts as JSON Schema, so an editor that reads it (taplo, Even Better TOML)
completes keys, shows each one's description and default, and marks a misspelt key, a
value of the wrong type, out of range or not among the choices, as the loader would
refuse it. Choices given as a function (the registries of robots, modes, sensors) are read
when the schema is made.

What the schema does not say, the loader still checks: the relations between fields (the
``_check`` of a block, e.g. ``record_tail_max >= record_tail``), that a number is finite,
and that an integer is written without a decimal point (JSON Schema takes ``1.0`` as an
integer). Keys of an older layout (``[mpc]`` for ``[loop.mpc]``) load with a warning but are
not in the schema.

The package ships the schema of :class:`AppConfig` beside its configurations
(:data:`SCHEMA_FILE`); ``ucat-console config schema --out FILE`` writes it again after a
change of the configuration (a test holds the shipped file equal to :func:`schema_text`).
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import types
import typing
from pathlib import Path
from typing import Any

from ucat_console import shipped
from ucat_console.config import AppConfig
from ucat_console.typedconf import check_value, choices_of

DRAFT = "https://json-schema.org/draft/2020-12/schema"

#: the schema's file name beside the shipped configurations (their ``#:schema`` directive names it)
SCHEMA_NAME = "ucat-console.schema.json"


def schema_of(cls: type) -> dict[str, Any]:
    """The JSON Schema of a config dataclass as a TOML table (its fields, nested tables)."""
    hints = typing.get_type_hints(cls)
    props: dict[str, Any] = {}
    required: list[str] = []
    for f in dataclasses.fields(cls):
        props[f.name], needed = _field_schema(f, hints[f.name])
        if needed:
            required.append(f.name)
    out: dict[str, Any] = {"type": "object"}
    doc = _class_doc(cls)
    if doc:
        out["description"] = doc
    out["properties"] = props
    if required:
        out["required"] = required
    out["additionalProperties"] = False
    return out


def app_schema() -> dict[str, Any]:
    """The schema of the whole configuration (:class:`AppConfig`, one TOML file)."""
    return {
        "$schema": DRAFT,
        "title": "ucat-console configuration",
        **schema_of(AppConfig),
    }


def schema_text() -> str:
    """:func:`app_schema` as the shipped file holds it."""
    return json.dumps(app_schema(), indent=2, allow_nan=False) + "\n"


def schema_path() -> Path:
    """The shipped schema's file, beside the shipped configurations."""
    return shipped.configs_dir() / SCHEMA_NAME


def _field_schema(f: dataclasses.Field, tp: Any) -> tuple[dict[str, Any], bool]:
    """A field's schema, and whether a file must give it (its default is refused by its own
    check, e.g. a sensor rule's name, which has to name a registered sensor)."""
    m = f.metadata
    out = _type_schema(tp)
    allowed = choices_of(f)
    if allowed is not None:
        out["enum"] = [_json_value(c) for c in allowed]
    elif out.get("type") in ("number", "integer"):
        if m.get("lo") is not None:
            out["exclusiveMinimum" if m.get("lo_open") else "minimum"] = m["lo"]
        if m.get("hi") is not None:
            out["exclusiveMaximum" if m.get("hi_open") else "maximum"] = m["hi"]
    description = _field_doc(f)
    if description:
        out = {"description": description, **out}
    default = _default(f)
    if default is dataclasses.MISSING:
        return out, True
    if default is not None and not dataclasses.is_dataclass(default) and not m.get("secret"):
        try:
            check_value(f, default)
        except ValueError:
            return out, True
        out["default"] = _json_value(default)
    return out, False


def _type_schema(tp: Any) -> dict[str, Any]:
    """The schema of a value of an annotated type, as :func:`typedconf.coerce` reads it."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        kinds = [_type_schema(a) for a in args if a is not type(None)]  # TOML has no null: left out
        return kinds[0] if len(kinds) == 1 else {"anyOf": kinds}
    if dataclasses.is_dataclass(tp):
        return schema_of(tp)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return {"type": "array", "items": _type_schema(args[0])}
        kinds = [_type_schema(a) for a in args]
        # one kind for all: "items" (read alike by every draft; taplo's reader knows no prefixItems)
        each = {"items": kinds[0]} if all(k == kinds[0] for k in kinds) else {"prefixItems": kinds}
        return {"type": "array", **each, "minItems": len(args), "maxItems": len(args)}
    if origin is typing.Literal:
        return {"enum": [_json_value(a) for a in args]}
    simple = {float: "number", int: "integer", bool: "boolean", str: "string"}
    if tp in simple:
        return {"type": simple[tp]}
    raise TypeError(f"no JSON Schema for the configuration type {tp!r}")


def _field_doc(f: dataclasses.Field) -> str:
    m = f.metadata
    doc = m.get("doc", "")
    if m.get("unit"):
        doc = f"{doc} ({m['unit']})" if doc else m["unit"]
    if m.get("secret"):
        doc += " (secret: never written to recordings or logs)"
    return doc


def _class_doc(cls: type) -> str:
    """A block's description: its docstring's first paragraph (not the one dataclass writes)."""
    doc = cls.__dict__.get("__doc__") or ""
    if doc.startswith(cls.__name__ + "("):
        return ""
    return " ".join(inspect.cleandoc(doc).split("\n\n")[0].split())


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


def _json_value(v: Any) -> Any:
    """A default or a choice as JSON holds it (tuples as arrays, tables as objects)."""
    if dataclasses.is_dataclass(v):
        return {f.name: _json_value(getattr(v, f.name)) for f in dataclasses.fields(v)
                if getattr(v, f.name) is not None}
    if isinstance(v, (tuple, list)):
        return [_json_value(x) for x in v]
    return v
