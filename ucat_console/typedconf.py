"""Typed, frozen configuration dataclasses: bounds, validation and TOML in/out.

Every configuration value in the project is a field of a frozen dataclass declared with
:func:`param`, which records its allowed range (or choices), unit and a one-line
description. The same metadata validates a value in ``__post_init__``, checks a TOML file,
and builds the console's tuning panels, so a bound is written once.

Nested dataclasses map to TOML tables. Unknown keys, wrong types, non-finite numbers and
out-of-range values raise :class:`ValueError` naming the dotted key and the allowed range.
:class:`Config` is the base of every configuration dataclass of the project.

Libraries: TOML is read by ``tomllib`` and written by ``tomli_w``; the validation below is
written by hand. msgspec (installed with viser) was considered for it and not taken, for
what msgspec 0.23 does with dataclasses: it checks ``Meta`` constraints only when
decoding or converting, never when a config is built in Python (``MpcConfig(lam_st=-1)``
and every tuning change from the page must be refused as well, so the checks here would
stay); it ignores unknown keys of a dataclass (``forbid_unknown_fields`` is for
``msgspec.Struct`` only, and a misspelt key must be refused); its errors name a path
(``$.mpc.lam_st``) but not the unit or an open bound; and the range, unit and doc of each
field, which the tuning panels are built from, would still need metadata of their own.
Moving every config class to ``msgspec.Struct`` would change the whole tree for one of
these (unknown keys).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Callable, Self, TypeVar

import tomli_w

T = TypeVar("T")

_MISSING = dataclasses.MISSING


def param(
    default: Any = _MISSING,
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    choices: tuple[Any, ...] | Callable[[], tuple[Any, ...]] | None = None,
    unit: str = "",
    doc: str = "",
    secret: bool = False,
    default_factory: Any = _MISSING,
) -> Any:
    """A dataclass field with bounds: ``lo <= value <= hi`` (open ends with ``*_open``).

    ``choices``: the values allowed, or a function returning them, read at every check (a
    registry that grows after import, e.g. the loop's modes; read them with :func:`choices_of`).

    ``secret``: the value is never written where others read it: :func:`to_dict` with
    ``redact=True`` (what recordings store) leaves it out, and the dataclass's repr (what
    a log line shows) does not show it."""
    meta = {
        "lo": lo,
        "hi": hi,
        "lo_open": lo_open,
        "hi_open": hi_open,
        "choices": choices,
        "unit": unit,
        "doc": doc,
        "secret": secret,
    }
    if default_factory is not _MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta, repr=not secret)
    return dataclasses.field(default=default, metadata=meta, repr=not secret)


def choices_of(f: dataclasses.Field) -> tuple[Any, ...] | None:
    """The values a choice field allows now (None: not a choice field)."""
    c = f.metadata.get("choices")
    return tuple(c()) if callable(c) else c


def describe_range(f: dataclasses.Field) -> str:
    """Human-readable allowed range of a field, e.g. ``[0.5, 8.0] rad/s``."""
    m = f.metadata
    allowed = choices_of(f)
    if allowed is not None:
        return "one of " + ", ".join(repr(c) for c in allowed)
    lo, hi = m.get("lo"), m.get("hi")
    left = "(" if m.get("lo_open") else "["
    right = ")" if m.get("hi_open") else "]"
    lo_s = "-inf" if lo is None else repr(lo)
    hi_s = "inf" if hi is None else repr(hi)
    unit = f" {m['unit']}" if m.get("unit") else ""
    return f"{left}{lo_s}, {hi_s}{right}{unit}"


def check_value(f: dataclasses.Field, value: Any, prefix: str = "") -> None:
    """Raise ValueError naming ``prefix + f.name`` when ``value`` is outside the field's range."""
    name = prefix + f.name
    m = f.metadata
    if not m:
        return
    allowed = choices_of(f)
    if allowed is not None:
        if value not in allowed:
            raise ValueError(f"{name}: {value!r} is not allowed; allowed: {describe_range(f)}")
        return
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        if m.get("lo") is None and m.get("hi") is None:
            return
        raise ValueError(f"{name}: expected a number in {describe_range(f)}, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"{name}: {value!r} is not finite; allowed: {describe_range(f)}")
    lo, hi = m.get("lo"), m.get("hi")
    bad = (
        (lo is not None and (value <= lo if m.get("lo_open") else value < lo))
        or (hi is not None and (value >= hi if m.get("hi_open") else value > hi))
    )
    if bad:
        raise ValueError(f"{name}: {value!r} is out of range; allowed: {describe_range(f)}")


def validate(obj: Any, prefix: str = "") -> None:
    """Check every field of a dataclass instance (call from ``__post_init__``): numbers
    must be of the annotated kind (an int where an int is declared; an int given for a
    float becomes a float) and inside their declared range."""
    hints = _field_types(type(obj))
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        tp = hints.get(f.name)
        if tp is int and (isinstance(value, bool) or not isinstance(value, int)):
            raise ValueError(f"{prefix}{f.name}: expected an integer, got {value!r}")
        if tp is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{prefix}{f.name}: expected a number, got {value!r}")
            if not isinstance(value, float):
                value = float(value)
                object.__setattr__(obj, f.name, value)
        check_value(f, value, prefix)


@functools.cache
def _field_types(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def coerce(tp: Any, value: Any, key: str) -> Any:
    """Convert a TOML value to the annotated type, refusing silent changes of kind."""
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        non_none = [a for a in args if a is not type(None)]
        last: Exception | None = None
        for a in non_none:
            try:
                return coerce(a, value, key)
            except ValueError as e:
                last = e
        raise last or ValueError(f"{key}: cannot read {value!r}")
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ValueError(f"{key}: expected a table, got {value!r}")
        return from_dict(tp, value, prefix=key + ".")
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"{key}: expected an array, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(coerce(args[0], v, f"{key}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ValueError(f"{key}: expected {len(args)} values, got {len(value)}")
        return tuple(coerce(a, v, f"{key}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{key}: expected a number, got {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{key}: expected an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ValueError(f"{key}: expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ValueError(f"{key}: expected a string, got {value!r}")
        return value
    if origin is typing.Literal:
        if value not in args:
            raise ValueError(f"{key}: {value!r} is not one of {', '.join(map(repr, args))}")
        return value
    return value


def from_dict(cls: type[T], data: dict[str, Any], prefix: str = "") -> T:
    """Build a config dataclass from a (TOML) dict; unknown keys are errors."""
    if not isinstance(data, dict):
        raise ValueError(f"{prefix or cls.__name__}: expected a table, got {data!r}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    hints = _field_types(cls)
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ValueError(
            f"{prefix}{unknown[0]}: unknown key; known keys: {', '.join(sorted(fields))}"
        )
    kwargs = {}
    for name, value in data.items():
        key = prefix + name
        kwargs[name] = coerce(hints[name], value, key)
        check_value(fields[name], kwargs[name], prefix)
    try:
        return cls(**kwargs)
    except ValueError as e:
        msg = str(e)
        raise ValueError(msg if not prefix or msg.startswith(prefix) else prefix + msg) from None


def to_dict(obj: Any, redact: bool = False) -> dict[str, Any]:
    """A TOML-ready dict of a config dataclass (None values are left out; with ``redact``,
    the fields declared ``secret`` too)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        if redact and f.metadata.get("secret"):
            continue
        v = getattr(obj, f.name)
        if v is None:
            continue
        if dataclasses.is_dataclass(v):
            out[f.name] = to_dict(v, redact)
        elif isinstance(v, tuple):
            out[f.name] = [to_dict(x, redact) if dataclasses.is_dataclass(x) else x for x in v]
        else:
            out[f.name] = v
    return out


def secret_values(obj: Any) -> list[str]:
    """The non-empty values of every ``secret`` field in a config tree (to keep out of logs)."""
    out: list[str] = []
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if f.metadata.get("secret") and isinstance(v, str) and v:
            out.append(v)
        elif dataclasses.is_dataclass(v):
            out += secret_values(v)
    return out


def load_toml(cls: type[T], path: str | Path) -> T:
    """Read a config dataclass from a TOML file, naming the file in any error (through
    ``cls.from_dict`` when the class defines one)."""
    p = Path(path)
    try:
        with p.open("rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise ValueError(f"{p}: configuration file not found") from None
    except IsADirectoryError:
        raise ValueError(f"{p}: is a directory, not a configuration file") from None
    except UnicodeDecodeError as e:
        raise ValueError(f"{p}: not a text file (byte {e.start} is not UTF-8); expected TOML") from None
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{p}: not valid TOML: {e}") from None
    build = getattr(cls, "from_dict", None) or (lambda d: from_dict(cls, d))
    try:
        return build(data)
    except ValueError as e:
        raise ValueError(f"{p}: {e}") from None


def dump_toml(obj: Any) -> str:
    return tomli_w.dumps(to_dict(obj))


def require_below(obj: Any, lo: str, hi: str, why: str = "") -> None:
    """Raise ValueError naming both fields unless ``obj.lo < obj.hi``."""
    a, b = getattr(obj, lo), getattr(obj, hi)
    if not a < b:
        reason = f" ({why})" if why else ""
        raise ValueError(f"{lo}/{hi}: need {lo} < {hi}{reason}, got {a} >= {b}")


class Config:
    """The base of every configuration dataclass: validation, TOML in/out, copies.

    Subclasses are ``@dataclass(frozen=True)`` with :func:`param` fields; ``_check`` holds
    the cross-field checks (run after every field has been checked).
    """

    def __post_init__(self) -> None:
        validate(self)
        self._check()

    def _check(self) -> None:  # cross-field checks
        pass

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Self:
        return from_dict(cls, data)

    @classmethod
    def from_toml(cls, path: str | Path) -> Self:
        return load_toml(cls, path)

    def to_toml(self) -> str:
        return dump_toml(self)

    def replace(self, **changes: Any) -> Self:
        return dataclasses.replace(self, **changes)
