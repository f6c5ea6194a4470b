"""Message dataclass <-> JSON bytes, and stream time <-> MCAP nanoseconds.

The encoding is the one documented in :mod:`ucat_console.backend.sessions.schema`
(NaN scalars left out, NaN array elements null, +/-inf as +/-1e999). Decoding checks every
field's kind and names the field in its ValueError: a file is input like any other.

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
from typing import Any, Callable

from ucat_console.backend.sessions.schema import (
    BOOL,
    FLOAT,
    FLOATS,
    INT,
    JSON,
    SEQ,
    STR,
    FieldSpec,
    field_specs,
)

NAN = float("nan")
_INF_TOKEN = "\x00ucat-inf\x00"  # placeholder while dumping; replaced by a bare 1e999
_PLACEHOLDERS = {
    json.dumps(_INF_TOKEN): "1e999",
    json.dumps("-" + _INF_TOKEN): "-1e999",
}


def to_ns(t: float, epoch_offset: float = 0.0) -> int:
    """Stream seconds ``t`` -> nanoseconds since the UNIX epoch (each term rounded on
    its own, so simulated times keep their nanoseconds under a large offset)."""
    return round(t * 1e9) + round(epoch_offset * 1e9)


def from_ns(ns: int, epoch_offset: float = 0.0) -> float:
    """Nanoseconds since the UNIX epoch -> stream seconds."""
    return (ns - round(epoch_offset * 1e9)) * 1e-9


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


def _inf_tokens(obj: dict[str, Any]) -> dict[str, Any]:
    def tok(x: Any) -> Any:
        if isinstance(x, float) and math.isinf(x):
            return _INF_TOKEN if x > 0 else "-" + _INF_TOKEN
        if isinstance(x, list):
            return [tok(y) for y in x]
        return x

    return {k: (v if isinstance(v, dict) else tok(v)) for k, v in obj.items()}


def _dumps(obj: dict[str, Any]) -> bytes:
    try:
        return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()
    except ValueError:  # an infinity somewhere
        text = json.dumps(_inf_tokens(obj), separators=(",", ":"), allow_nan=False)
        for token, number in _PLACEHOLDERS.items():
            text = text.replace(token, number)
        return text.encode()


def _make_encoder(cls: type) -> Callable[[Any], dict[str, Any]]:
    specs = field_specs(cls)

    def to_obj(msg: Any) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for s in specs:
            v = getattr(msg, s.name)
            if v is None and s.optional:
                continue
            try:
                kind = s.kind
                if kind == FLOAT:
                    if v != v:  # NaN: left out
                        continue
                    out[s.name] = _float_out(v)
                elif kind == FLOATS:
                    if len(v) != s.length:
                        raise ValueError(f"expected {s.length} values, got {len(v)}")
                    out[s.name] = [None if x != x else _float_out(x) for x in v]
                elif kind == INT:
                    if isinstance(v, bool) or not isinstance(v, int):
                        raise ValueError(f"expected an integer, got {v!r}")
                    out[s.name] = v
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
        return out

    return to_obj


@functools.cache
def _encoder(cls: type) -> Callable[[Any], dict[str, Any]]:
    return _make_encoder(cls)



def encode(msg: Any) -> bytes:
    """A message dataclass -> compact JSON bytes (ValueError naming a bad field)."""
    return _dumps(_encoder(type(msg))(msg))


# ---------------------------------------------------------------------- decoding
def _float_in(v: Any, where: str) -> float:
    if v is None:
        return NAN
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"{where}: expected a number, got {v!r}")
    return float(v)


_ITEM_CHECK = {
    INT: lambda x: isinstance(x, int) and not isinstance(x, bool),
    BOOL: lambda x: isinstance(x, bool),
    STR: lambda x: isinstance(x, str),
}


def _field_in(s: FieldSpec, v: Any, where: str) -> Any:
    kind = s.kind
    if kind == FLOAT:
        return _float_in(v, where)
    if kind == FLOATS:
        if not isinstance(v, list) or len(v) != s.length:
            raise ValueError(f"{where}: expected an array of {s.length} numbers, got {v!r}")
        return tuple(_float_in(x, f"{where}[{i}]") for i, x in enumerate(v))
    if kind == INT:
        if isinstance(v, bool) or not isinstance(v, int):
            raise ValueError(f"{where}: expected an integer, got {v!r}")
        return v
    if kind == BOOL:
        if not isinstance(v, bool):
            raise ValueError(f"{where}: expected true or false, got {v!r}")
        return v
    if kind == STR:
        if not isinstance(v, str):
            raise ValueError(f"{where}: expected a string, got {v!r}")
        return v
    if kind == SEQ:
        check = _ITEM_CHECK[s.item]
        if not isinstance(v, list) or not all(check(x) for x in v):
            raise ValueError(f"{where}: expected an array of {s.item}, got {v!r}")
        return tuple(v)
    if kind == JSON:
        if not isinstance(v, dict):
            raise ValueError(f"{where}: expected an object, got {v!r}")
        return v
    raise AssertionError(kind)


def from_json_obj(cls: type, obj: Any) -> Any:
    """Build a ``cls`` message from its JSON object (ValueError naming a bad field)."""
    name = cls.__name__
    if not isinstance(obj, dict):
        raise ValueError(f"{name}: expected a JSON object, got {type(obj).__name__}")
    specs = field_specs(cls)
    known = {s.name for s in specs}
    unknown = [k for k in obj if k not in known]
    if unknown:
        raise ValueError(f"{name}.{unknown[0]}: unknown field")
    kwargs: dict[str, Any] = {}
    for s in specs:
        where = f"{name}.{s.name}"
        if s.name not in obj or (obj[s.name] is None and s.optional):
            if s.optional:
                kwargs[s.name] = None
            elif s.kind == FLOAT:
                kwargs[s.name] = NAN
            else:
                raise ValueError(f"{where}: missing")
            continue
        kwargs[s.name] = _field_in(s, obj[s.name], where)
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name}: {e}") from None


def decode(cls: type, data: bytes) -> Any:
    """JSON bytes -> a ``cls`` message (ValueError naming what is wrong)."""
    try:
        obj = json.loads(data)
    except (ValueError, UnicodeDecodeError) as e:
        raise ValueError(f"{cls.__name__}: message is not valid JSON ({e})") from None
    return from_json_obj(cls, obj)
