"""CSV export: one file per channel, columns flattened from the message dataclass.

File names: the channel name with ``/`` replaced by ``_`` (``fin/0/state`` ->
``fin_0_state.csv``). Columns, in field order, after ``log_time_ns`` (the file's UNIX
nanoseconds; ``t`` is the message's own time field):

    scalar field            its name                          ``depth``
    fixed-length tuple      ``name.i`` for each element i     ``position.0``, ``position.1``
    variable-length tuple   its name, elements joined by ";"  ``failsafes``
    dict (Event.data)       its name, as compact JSON         ``data``

Floats are written with ``repr`` (they read back exactly; NaN as ``nan``, infinities as
``inf``/``-inf``), booleans as ``true``/``false``, a field that is None as empty cells.
The columns depend only on the message type, never on the data.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any, Iterable, Sequence

from ucat_console.backend.sessions.reader import SessionParts, SessionReader, SessionSource
from ucat_console.backend.sessions.schema import BOOL, FLOAT, FLOATS, JSON, SEQ, field_specs
from ucat_console.telemetry.channels import message_type

TIME_COLUMN = "log_time_ns"


def csv_name(channel: str) -> str:
    return channel.replace("/", "_") + ".csv"


def columns(cls: type) -> list[str]:
    """The CSV header of message type ``cls``."""
    out = [TIME_COLUMN]
    for s in field_specs(cls):
        if s.kind == FLOATS:
            out += [f"{s.name}.{i}" for i in range(s.length)]
        else:
            out.append(s.name)
    return out


def _cell(kind: str, v: Any) -> str:
    if kind == FLOAT:
        return repr(float(v))
    if kind == BOOL:
        return "true" if v else "false"
    if kind == SEQ:
        return ";".join("true" if x is True else "false" if x is False else str(x) for x in v)
    if kind == JSON:
        return json.dumps(v, separators=(",", ":"), sort_keys=True)
    return str(v)


def row(msg: Any, log_time_ns: int) -> list[str]:
    """One CSV row of a message (aligned with :func:`columns`)."""
    out = [str(log_time_ns)]
    for s in field_specs(type(msg)):
        v = getattr(msg, s.name)
        if s.kind == FLOATS:
            out += [""] * s.length if v is None else [repr(float(x)) for x in v]
        elif v is None:
            out.append("")
        else:
            out.append(_cell(s.kind, v))
    return out


def export_csv(
    readers: SessionSource | Sequence[SessionSource],
    channels: Iterable[str],
    out_dir: str | Path,
    start: float | None = None,
    end: float | None = None,
) -> dict[str, tuple[Path, int]]:
    """Write one CSV per channel into ``out_dir``: the messages of ``readers`` (a part, a
    whole session as :class:`SessionParts`, or several of them, in the order given).

    Returns channel -> (file, rows). Unknown channel names raise ValueError; a channel
    with no messages gets a file with its header only.
    """
    if isinstance(readers, (SessionReader, SessionParts)):
        readers = [readers]
    chans = list(dict.fromkeys(channels))
    if not chans:
        raise ValueError("topics: no channel given")
    types = {c: message_type(c) for c in chans}  # ValueError for an unknown name
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out: {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    result: dict[str, tuple[Path, int]] = {}
    for c in chans:
        path = out / csv_name(c)
        n = 0
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(columns(types[c]))
            for r in readers:
                for rec in r.records([c], start, end):
                    w.writerow(row(rec.message, rec.log_time_ns))
                    n += 1
        result[c] = (path, n)
    return result
