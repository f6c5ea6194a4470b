"""CSV export: one file per channel, columns flattened from the message dataclass, and a
sidecar describing every column.

File names: the channel name with ``/`` replaced by ``_`` (``fin/0/state`` ->
``fin_0_state.csv``), and beside it ``fin_0_state.columns.json``. Columns, in field order,
after ``log_time_ns`` (the file's UNIX nanoseconds; ``t`` is the message's own time field),
named by their MCAP message paths (as Foxglove and PlotJuggler name them):

    scalar field                 its name                       ``depth``
    named vector                 ``name.part`` for each part    ``position.x``, ``orientation.x``
    per-fin array                ``name[i]`` for each element   ``per_fin[0]`` ... ``per_fin[3]``
    variable-length tuple        its name, as a JSON array      ``failsafes``: ``[]``, ``["dvl"]``
    dict (Event.data)            its name, as compact JSON      ``data``

One dtype per column, whatever the data (the sidecar names it): ``float64`` (``repr``, so
values read back exactly; ``nan``, ``inf``, ``-inf`` for non-finite ones), ``int64``,
``bool`` (``true``/``false``), ``string``, ``json`` (JSON text), and ``decimal`` for
integers that may exceed 2^63 (planner seeds, -1 for none): written as decimal text, to be
read as text (``pandas.read_csv(..., dtype={"seed": str})``) and converted with ``int``,
since a float64 or an int64 column would change them.

Missing and empty stay apart: a value is *missing* only where a field is optional and
absent (an IMU reading without orientation): its cells are empty, and only columns the
sidecar marks ``"nullable": true`` can have them. Text is never missing, so an empty
cell in a ``string`` column is the empty string (read text columns with
``keep_default_na=False`` in pandas, which otherwise reads an empty cell as NaN), and an
empty list is ``[]``.

The sidecar (``*.columns.json``) is a Frictionless Tabular Data Resource (Data Package
v2: ``frictionless validate body_state.columns.json`` checks the CSV against it): the CSV's
``path`` and ``dialect``, and in ``schema`` a Table Schema with one field per column, in
order: its ``name``, Table Schema ``type`` (``number`` for float64, which takes ``nan``,
``inf`` and ``-inf``; ``integer``; ``boolean`` with ``true``/``false``; ``string``;
``array`` and ``object`` for JSON text), ``description`` (the field's schema description
with its unit and frame), ``unit`` (a symbol a units library parses, as in the session
schemas), the exporter's ``dtype`` (above; ``decimal``: read it as text), and
``constraints.required`` unless the column may be missing, in which case its
``missingValues`` is ``[""]`` (the schema's own is ``[]``: an empty cell elsewhere is the
empty string).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any, Iterable, Sequence

from ucat_console.backend.sessions import images
from ucat_console.backend.sessions.reader import SessionParts, SessionReader, SessionSource
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
from ucat_console.robot.fields import WXYZ
from ucat_console.telemetry.channels import message_type

TIME_COLUMN = "log_time_ns"
SIDECAR_SUFFIX = ".columns.json"
_DTYPES = {FLOAT: "float64", FLOATS: "float64", INT: "int64", BOOL: "bool", STR: "string",
           SEQ: "json", JSON: "json"}
#: the Table Schema type of each field kind
_TABLE_TYPES = {FLOAT: "number", FLOATS: "number", INT: "integer", BOOL: "boolean", STR: "string",
                SEQ: "array", JSON: "object"}
DATA_RESOURCE = "https://datapackage.org/profiles/2.0/dataresource.json"
TABLE_SCHEMA = "https://datapackage.org/profiles/2.0/tableschema.json"
TABLE_DIALECT = "https://datapackage.org/profiles/2.0/tabledialect.json"


def csv_name(channel: str) -> str:
    return channel.replace("/", "_") + ".csv"


def sidecar_name(channel: str) -> str:
    return channel.replace("/", "_") + SIDECAR_SUFFIX


def _dtype(s: FieldSpec) -> str:
    return "decimal" if s.kind == INT and s.wide else _DTYPES[s.kind]


def _order(s: FieldSpec) -> range | tuple[int, ...]:
    """The order of a field's numbers in the CSV: a quaternion x, y, z, w as in the MCAP
    messages (the Python messages hold it w first), everything else as held."""
    return (1, 2, 3, 0) if s.names == WXYZ else range(s.length)


def _field(name: str, kind: str, dtype: str, unit: str, optional: bool, description: str) -> dict[str, Any]:
    """One Table Schema field."""
    out: dict[str, Any] = {"name": name, "type": _TABLE_TYPES[kind], "description": description}
    if unit:
        out["unit"] = unit
    out["dtype"] = dtype
    if kind == BOOL:
        out.update(trueValues=["true"], falseValues=["false"])
    if optional:
        out["missingValues"] = [""]
    else:
        out["constraints"] = {"required": True}
    return out


def column_specs(cls: type) -> list[dict[str, Any]]:
    """The Table Schema field of each column of message type ``cls``."""
    out = [_field(TIME_COLUMN, INT, "int64", "ns", False,
                  "the message's file time, nanoseconds since the UNIX epoch")]
    for s in field_specs(cls):
        doc = s.doc
        paths = s.paths()
        order = list(_order(s)) if s.kind == FLOATS else [0]
        units = doc.units(s.length or 1) if doc is not None else ("",) * (s.length or 1)
        for i in order:
            out.append(_field(paths[i], s.kind, _dtype(s), units[i], s.optional,
                              doc.describe() if doc is not None else ""))
    return out


def columns(cls: type) -> list[str]:
    """The CSV header of message type ``cls``."""
    return [c["name"] for c in column_specs(cls)]


def data_resource(channel: str, cls: type) -> dict[str, Any]:
    """The sidecar of a channel's CSV: a Tabular Data Resource with its Table Schema."""
    name = csv_name(channel).removesuffix(".csv")
    return {
        "$schema": DATA_RESOURCE,
        "name": name,
        "type": "table",
        "path": csv_name(channel),
        "format": "csv",
        "mediatype": "text/csv",
        "encoding": "utf-8",
        "title": f"session channel {channel}",
        "description": (cls.__doc__ or cls.__name__).strip().splitlines()[0],
        "channel": channel,
        "dialect": {"$schema": TABLE_DIALECT, "header": True, "delimiter": ",", "quoteChar": '"',
                    "doubleQuote": True},
        "schema": {"$schema": TABLE_SCHEMA, "fields": column_specs(cls), "missingValues": [],
                   "fieldsMatch": "exact"},
    }


def _cell(s: FieldSpec, v: Any) -> str:
    kind = s.kind
    if kind == FLOAT:
        return repr(float(v))
    if kind == BOOL:
        return "true" if v else "false"
    if kind == SEQ:
        return json.dumps(list(v), separators=(",", ":"))
    if kind == JSON:
        return json.dumps(v, separators=(",", ":"), sort_keys=True)
    return str(v)


def row(msg: Any, log_time_ns: int) -> list[str]:
    """One CSV row of a message (aligned with :func:`columns`)."""
    out = [str(log_time_ns)]
    for s in field_specs(type(msg)):
        v = getattr(msg, s.name)
        if s.kind == FLOATS:
            out += [""] * s.length if v is None else [repr(float(v[i])) for i in _order(s)]
        elif v is None:
            out.append("")
        else:
            out.append(_cell(s, v))
    return out


def export_csv(
    readers: SessionSource | Sequence[SessionSource],
    channels: Iterable[str],
    out_dir: str | Path,
    start: float | None = None,
    end: float | None = None,
) -> dict[str, tuple[Path, int]]:
    """Write one CSV per channel, with its sidecar, into ``out_dir``: the messages of
    ``readers`` (a part, a whole session as :class:`SessionParts`, or several of them, in
    the order given).

    Returns channel -> (file, rows). Unknown channel names raise ValueError; a channel
    with no messages gets a file with its header only.
    """
    if isinstance(readers, (SessionReader, SessionParts)):
        readers = [readers]
    chans = list(dict.fromkeys(channels))
    if not chans:
        raise ValueError("topics: no channel given")
    types = {c: message_type(c) for c in chans}  # ValueError for an unknown name
    pictures = [c for c, cls in types.items() if images.is_image(cls)]
    if pictures:
        raise ValueError(f"topics: {', '.join(pictures)} holds pictures, which a CSV file cannot "
                         "(Foxglove shows them from the session file)")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out: {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    result: dict[str, tuple[Path, int]] = {}
    for c in chans:
        path = out / csv_name(c)
        resource = data_resource(c, types[c])
        specs = resource["schema"]["fields"]
        (out / sidecar_name(c)).write_text(json.dumps(resource, indent=1) + "\n")
        n = 0
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow([s["name"] for s in specs])
            for r in readers:
                for rec in r.records([c], start, end):
                    w.writerow(row(rec.message, rec.log_time_ns))
                    n += 1
        result[c] = (path, n)
    return result
