"""Message dataclass <-> JSON bytes, and stream time <-> MCAP nanoseconds.

The encoding is the one documented in :mod:`ucat_console.backend.sessions.schema`
(encoding 2: named vectors, wide integers as strings, non-finite numbers left out and
listed in ``nonfinite``). Decoding checks every field's kind and names the field in its
ValueError: a file is input like any other. Files of encoding 1 are decoded by
:mod:`ucat_console.backend.sessions.legacy`.

Time: a message's ``t`` is seconds on the stream's clock; a session file stores
``log_time = publish_time = round(t * 1e9) + round(epoch_offset * 1e9)``, nanoseconds
since the UNIX epoch (``epoch_offset`` is 0 for wall-clock runs, the run's start for
headless runs).
:func:`to_ns` and :func:`from_ns` are the one conversion each way.
"""

from __future__ import annotations

import functools
import json
import math
import re
import reprlib
from typing import Any, Callable

import msgspec

from ucat_console.backend.sessions.limits import MAX_JSON_DEPTH
from ucat_console.backend.sessions.schema import (
    BOOL,
    FLOAT,
    FLOATS,
    INT,
    JSON,
    NONFINITE,
    NONFINITE_VALUES,
    SEQ,
    STR,
    WIDE_PATTERN,
    FieldSpec,
    field_specs,
)
from ucat_console.robot.units import GRAVITY

_WIDE = re.compile(WIDE_PATTERN)


def to_ns(t: float, epoch_offset: float = 0.0) -> int:
    """Stream seconds ``t`` -> nanoseconds since the UNIX epoch (each term rounded on
    its own, so simulated times keep their nanoseconds under a large offset)."""
    return round(t * 1e9) + round(epoch_offset * 1e9)


def from_ns(ns: int, epoch_offset: float = 0.0) -> float:
    """Nanoseconds since the UNIX epoch -> stream seconds."""
    return (ns - round(epoch_offset * 1e9)) * 1e-9


def nonfinite_name(x: float) -> str:
    """"nan", "inf" or "-inf"."""
    return "nan" if x != x else ("inf" if x > 0 else "-inf")


# ---------------------------------------------------------------------- encoding
def _float_out(v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"expected a number, got {v!r}")
    return float(v)


def _sanitize_json(v: Any) -> Any:
    """Free-form JSON values: non-finite numbers become null."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {str(k): _sanitize_json(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_sanitize_json(x) for x in v]
    return v


def _make_encoder(cls: type) -> Callable[[Any], dict[str, Any]]:
    specs = field_specs(cls)

    def to_obj(msg: Any) -> dict[str, Any]:
        out: dict[str, Any] = {}
        bad: dict[str, str] = {}
        for s in specs:
            v = getattr(msg, s.name)
            if v is None and s.optional:
                continue
            try:
                kind = s.kind
                if kind == FLOAT:
                    x = v if type(v) is float else _float_out(v)
                    if math.isfinite(x):
                        out[s.name] = x
                    else:
                        bad[s.name] = nonfinite_name(x)
                elif kind == FLOATS:
                    if len(v) != s.length:
                        raise ValueError(f"expected {s.length} values, got {len(v)}")
                    xs = [x if type(x) is float else _float_out(x) for x in v]
                    if math.isfinite(sum(xs)):  # all finite (one that is not makes the sum so)
                        out[s.name] = dict(zip(s.names, xs)) if s.names else xs
                    elif s.names:
                        obj = {}
                        for n, x in zip(s.names, xs):
                            if math.isfinite(x):
                                obj[n] = x
                            else:
                                bad[f"{s.name}.{n}"] = nonfinite_name(x)
                        out[s.name] = obj
                    else:
                        for i, x in enumerate(xs):
                            if not math.isfinite(x):
                                bad[f"{s.name}[{i}]"] = nonfinite_name(x)
                                xs[i] = None  # type: ignore[call-overload]
                        out[s.name] = xs
                elif kind == INT:
                    if isinstance(v, bool) or not isinstance(v, int):
                        raise ValueError(f"expected an integer, got {v!r}")
                    out[s.name] = str(v) if s.wide else v
                elif kind == BOOL:
                    out[s.name] = bool(v)
                elif kind == STR:
                    if not isinstance(v, str):
                        raise ValueError(f"expected a string, got {v!r}")
                    out[s.name] = v
                elif kind == SEQ:
                    out[s.name] = list(v)
                else:  # JSON
                    out[s.name] = _sanitize_json(dict(v))
            except (TypeError, ValueError) as e:
                raise ValueError(f"{cls.__name__}.{s.name}: {e}") from None
        if bad:
            out[NONFINITE] = bad
        return out

    return to_obj


def _make_fast_encoder(cls: type, slow: Callable[[Any], dict[str, Any]]) -> Callable[[Any], dict[str, Any]] | None:
    """The encoder of :func:`_make_encoder` for ``cls``, with a fast path written out for
    the class's fields (None when a field is of a kind without one: SEQ, JSON).

    The fast path takes the common message: every FLOAT a float and every FLOATS a tuple of
    floats of its length, all finite (checked by one sum: a value that is not makes the
    sum so), INT an int, BOOL a bool, STR a str, no optional field left out. It builds the
    same object as the general encoder, which takes every other message; the recorder
    encodes some 500 messages a second, and the general loop over the fields was the
    larger part of its CPU."""
    specs = field_specs(cls)
    fetch, checks, floats, items = [], [], [], []
    for i, s in enumerate(specs):
        v = f"v{i}"
        fetch.append(f"    {v} = msg.{s.name}")
        if s.kind == FLOAT:
            checks.append(f"type({v}) is float")
            floats.append(v)
            items.append(f"{s.name!r}: {v}")
        elif s.kind == FLOATS:
            xs = [f"{v}[{j}]" for j in range(s.length)]
            checks.append(f"type({v}) is tuple and len({v}) == {s.length}")
            checks.extend(f"type({x}) is float" for x in xs)
            floats.extend(xs)
            if s.names:
                items.append(f"{s.name!r}: {{{', '.join(f'{n!r}: {x}' for n, x in zip(s.names, xs))}}}")
            else:
                items.append(f"{s.name!r}: [{', '.join(xs)}]")
        elif s.kind == INT:
            checks.append(f"type({v}) is int")
            items.append(f"{s.name!r}: str({v})" if s.wide else f"{s.name!r}: {v}")
        elif s.kind == BOOL:
            checks.append(f"type({v}) is bool")
            items.append(f"{s.name!r}: {v}")
        elif s.kind == STR:
            checks.append(f"type({v}) is str")
            items.append(f"{s.name!r}: {v}")
        else:
            return None
    if floats:
        checks.append(f"_isfinite({' + '.join(floats)})")
    src = "\n".join([
        "def to_obj(msg):",
        *fetch,
        f"    if {' and '.join(checks) or 'True'}:",
        f"        return {{{', '.join(items)}}}",
        "    return _slow(msg)",
    ])
    scope: dict[str, Any] = {"_isfinite": math.isfinite, "_slow": slow}
    exec(compile(src, f"<codec encoder of {cls.__name__}>", "exec"), scope)
    return scope["to_obj"]


@functools.cache
def _encoder(cls: type) -> Callable[[Any], dict[str, Any]]:
    slow = _make_encoder(cls)
    return _make_fast_encoder(cls, slow) or slow


_JSON = msgspec.json.Encoder()


def compact_json(obj: Any) -> bytes:
    """``obj`` (dicts, lists, strings, numbers) as compact JSON bytes, by msgspec: seven
    times faster than the standard library's encoder, which the recorder would spend most of
    its time in (a thousand messages a second at the pool). The numbers must be finite:
    msgspec writes a non-finite one as null, and every caller has taken them out already
    (the codec names them in the message's ``nonfinite`` field; a derived Foxglove message is
    not made from a non-finite value)."""
    return _JSON.encode(obj)


def encode(msg: Any) -> bytes:
    """A message dataclass -> compact JSON bytes (ValueError naming a bad field)."""
    return compact_json(_encoder(type(msg))(msg))


# ---------------------------------------------------------------------- decoding
def _number(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"{where}: expected a number, got {short(v)}")
    return float(v)


_ITEM_CHECK = {
    INT: lambda x: isinstance(x, int) and not isinstance(x, bool),
    BOOL: lambda x: isinstance(x, bool),
    STR: lambda x: isinstance(x, str),
}


class _NonFinite:
    """The message's ``nonfinite`` listing; each entry must be taken by a missing value."""

    def __init__(self, listing: Any, where: str) -> None:
        if listing is None:
            listing = {}
        if not isinstance(listing, dict) or not all(
            isinstance(v, str) and v in NONFINITE_VALUES for v in listing.values()
        ):
            raise ValueError(f"{where}.{NONFINITE}: expected an object of nan / inf / -inf, "
                             f"got {short(listing)}")
        self.left = dict(listing)
        self.where = where

    def take(self, path: str) -> float:
        try:
            return NONFINITE_VALUES[self.left.pop(path)]
        except KeyError:
            raise ValueError(f"{self.where}.{path}: missing") from None

    def check_used(self) -> None:
        if self.left:
            path = next(iter(self.left))
            raise ValueError(f"{self.where}.{NONFINITE}: {short(path)} names no missing value")


def _field_in(s: FieldSpec, v: Any, where: str, nonfinite: _NonFinite) -> Any:
    kind = s.kind
    if kind == FLOAT:
        return _number(v, where)
    if kind == FLOATS:
        if s.names:
            if not isinstance(v, dict):
                raise ValueError(f"{where}: expected an object of {', '.join(s.names)}, got {short(v)}")
            unknown = [k for k in v if k not in s.names]
            if unknown:
                raise ValueError(f"{where}.{_name(unknown[0])}: unknown field")
            return tuple(
                _number(v[n], f"{where}.{n}") if n in v else nonfinite.take(f"{s.name}.{n}")
                for n in s.names
            )
        if not isinstance(v, list) or len(v) != s.length:
            raise ValueError(f"{where}: expected an array of {s.length} numbers, got {short(v)}")
        return tuple(
            nonfinite.take(f"{s.name}[{i}]") if x is None else _number(x, f"{where}[{i}]")
            for i, x in enumerate(v)
        )
    if kind == INT:
        if s.wide:
            if not isinstance(v, str) or not _WIDE.match(v):
                raise ValueError(f"{where}: expected an integer as a decimal string, got {short(v)}")
            return int(v)
        if isinstance(v, bool) or not isinstance(v, int):
            raise ValueError(f"{where}: expected an integer, got {short(v)}")
        return v
    if kind == BOOL:
        if not isinstance(v, bool):
            raise ValueError(f"{where}: expected true or false, got {short(v)}")
        return v
    if kind == STR:
        if not isinstance(v, str):
            raise ValueError(f"{where}: expected a string, got {short(v)}")
        return v
    if kind == SEQ:
        check = _ITEM_CHECK[s.item]
        if not isinstance(v, list) or not all(check(x) for x in v):
            raise ValueError(f"{where}: expected an array of {s.item}, got {short(v)}")
        return tuple(v)
    if kind == JSON:
        if not isinstance(v, dict):
            raise ValueError(f"{where}: expected an object, got {short(v)}")
        if json_depth(v) > MAX_JSON_DEPTH:
            raise ValueError(f"{where}: nested deeper than {MAX_JSON_DEPTH} levels")
        return v
    raise AssertionError(kind)


def from_json_obj(cls: type, obj: Any) -> Any:
    """Build a ``cls`` message from its JSON object (ValueError naming a bad field)."""
    name = cls.__name__
    if not isinstance(obj, dict):
        raise ValueError(f"{name}: expected a JSON object, got {type(obj).__name__}")
    specs = field_specs(cls)
    known = {s.name for s in specs}
    unknown = [k for k in obj if k not in known and k != NONFINITE]
    if unknown:
        raise ValueError(f"{name}.{_name(unknown[0])}: unknown field")
    nonfinite = _NonFinite(obj.get(NONFINITE), name)
    kwargs: dict[str, Any] = {}
    for s in specs:
        where = f"{name}.{s.name}"
        if s.name not in obj:
            if s.optional:
                kwargs[s.name] = None
            elif s.kind == FLOAT:
                kwargs[s.name] = nonfinite.take(s.name)
            else:
                raise ValueError(f"{where}: missing")
            continue
        kwargs[s.name] = _field_in(s, obj[s.name], where, nonfinite)
    nonfinite.check_used()
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name}: {e}") from None


def json_depth(obj: Any) -> int:
    """How deep ``obj``'s objects and arrays nest (0 for a plain value), counted without
    recursion."""
    deepest = 0
    todo = [(obj, 1)]
    while todo:
        v, d = todo.pop()
        if isinstance(v, dict):
            items: Any = v.values()
        elif isinstance(v, list):
            items = v
        else:
            continue
        deepest = max(deepest, d)
        if deepest > MAX_JSON_DEPTH:
            break
        todo.extend((x, d + 1) for x in items if isinstance(x, (dict, list)))
    return deepest


def load_json(data: bytes | str, what: str) -> Any:
    """The JSON value of ``data`` read from a file (ValueError naming ``what`` when it is not
    JSON or nests deeper than :data:`~.limits.MAX_JSON_DEPTH`)."""
    try:
        obj = json.loads(data)
    except RecursionError:
        raise ValueError(f"{what}: JSON nested deeper than {MAX_JSON_DEPTH} levels") from None
    except (ValueError, UnicodeDecodeError) as e:
        raise ValueError(f"{what}: not valid JSON ({str(e)[:120]})") from None
    if json_depth(obj) > MAX_JSON_DEPTH:
        raise ValueError(f"{what}: JSON nested deeper than {MAX_JSON_DEPTH} levels")
    return obj


_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxstring, _REPR.maxother, _REPR.maxdict, _REPR.maxlist = 3, 60, 60, 6, 6


def short(v: Any, n: int = 80) -> str:
    """``repr(v)`` within ``n`` characters and three levels of nesting: a file's value in an
    error message (which a crafted file could otherwise make megabytes long)."""
    text = _REPR.repr(v)
    return text if len(text) <= n else text[: n - 3] + "..."


def _name(key: str) -> str:
    """A field name from a file, cut for an error message."""
    return key if len(key) <= 60 else key[:57] + "..."


def loads(cls: type, data: bytes) -> Any:
    """The JSON object of a message's bytes (ValueError when they are not JSON)."""
    try:
        return json.loads(data)
    except RecursionError:
        raise ValueError(f"{cls.__name__}: message nests deeper than {MAX_JSON_DEPTH} levels") from None
    except (ValueError, UnicodeDecodeError) as e:
        raise ValueError(f"{cls.__name__}: message is not valid JSON ({str(e)[:120]})") from None


#: fields a message type once had under another name and unit: type name -> (the former
#: name, the present one, the factor from the former unit to the present one); a session
#: recorded before the change keeps opening, the former field read as the present one
FORMER_FIELDS: dict[str, tuple[str, str, float]] = {
    "ImuReading": ("accel_g", "accel", GRAVITY),  # standard gravities -> m/s^2
}


def _scaled(v: Any, factor: float) -> Any:
    """A number, or an array or object of numbers, times ``factor`` (anything else as it
    is, for the decoder to judge)."""
    def one(x: Any) -> Any:
        return x * factor if isinstance(x, (int, float)) and not isinstance(x, bool) else x
    if isinstance(v, list):
        return [one(x) for x in v]
    if isinstance(v, dict):
        return {k: one(x) for k, x in v.items()}
    return one(v)


def from_former_fields(cls: type, obj: Any) -> Any:
    """``obj`` (a ``cls`` message's JSON object) with a field of :data:`FORMER_FIELDS`
    renamed and converted to its present unit, its non-finite entries renamed with it."""
    former = FORMER_FIELDS.get(cls.__name__)
    if former is None or not isinstance(obj, dict):
        return obj
    old, new, factor = former
    if old not in obj or new in obj:
        return obj
    out = dict(obj)
    out[new] = _scaled(out.pop(old), factor)
    listed = out.get(NONFINITE)
    if isinstance(listed, dict):
        out[NONFINITE] = {(new + k[len(old):] if k == old or k.startswith(old + ".") else k): x
                          for k, x in listed.items()}
    return out


def decode(cls: type, data: bytes) -> Any:
    """JSON bytes -> a ``cls`` message (ValueError naming what is wrong)."""
    return from_json_obj(cls, from_former_fields(cls, loads(cls, data)))
