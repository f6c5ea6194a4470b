"""Reading session files of encoding 1 (written before encoding 2; schemas without ``$id``).

Encoding 1 held every fixed-length tuple as an array (a quaternion w first), a NaN scalar
as a missing key, a NaN array element as ``null``, +/-inf as the JSON numbers
``1e999``/``-1e999`` (Python's JSON parser reads them back as infinities) and the planner
seed as a JSON number. Such files stay on operators' disks: :func:`decode` rewrites each
message's JSON object into encoding 2 and decodes that, so both encodings give the same
dataclasses through one decoder. Nothing writes encoding 1 any more.
"""

from __future__ import annotations

import math
from typing import Any

from ucat_console.backend.sessions import codec
from ucat_console.backend.sessions.schema import FLOAT, FLOATS, INT, NONFINITE, field_specs


def _finite(x: Any) -> bool:
    return not isinstance(x, float) or math.isfinite(x)


def upgrade(cls: type, obj: Any) -> Any:
    """An encoding-1 JSON object of a ``cls`` message as encoding 2 writes it (values that
    are not what encoding 1 wrote are left for the decoder to refuse)."""
    if not isinstance(obj, dict):
        return obj
    if NONFINITE in obj:
        raise ValueError(f"{cls.__name__}.{NONFINITE}: unknown field")
    out = dict(obj)
    bad: dict[str, str] = {}
    for s in field_specs(cls):
        where = f"{cls.__name__}.{s.name}"
        v = obj.get(s.name)
        if s.name in obj and v is None and s.optional:
            del out[s.name]
        elif s.kind == FLOAT:
            if s.name not in obj:
                bad[s.name] = "nan"
            elif not _finite(v):
                del out[s.name]
                bad[s.name] = codec.nonfinite_name(v)
        elif s.kind == FLOATS and s.name in obj:
            if not isinstance(v, list) or len(v) != s.length:
                raise ValueError(f"{where}: expected an array of {s.length} numbers, got {v!r}")
            xs = []
            for path, x in zip(s.paths(), v):
                if x is None or not _finite(x):
                    bad[path] = "nan" if x is None else codec.nonfinite_name(x)
                    x = None
                xs.append(x)
            if s.names:
                out[s.name] = {n: x for n, x in zip(s.names, xs) if x is not None}
            else:
                out[s.name] = xs
        elif s.kind == INT and s.wide and isinstance(v, int) and not isinstance(v, bool):
            out[s.name] = str(v)
    if bad:
        out[NONFINITE] = bad
    return out


def decode(cls: type, data: bytes) -> Any:
    """Encoding-1 JSON bytes -> a ``cls`` message (ValueError naming what is wrong)."""
    return codec.from_json_obj(cls, upgrade(cls, codec.from_former_fields(cls, codec.loads(cls, data))))
