"""Session files from Python: each channel as NumPy arrays (or a pandas DataFrame) with units.

::

    import ucat_console.sessions

    with ucat_console.sessions.open("20261204-101500-pool_001.mcap") as rec:
        rec.channels                       # ['body/state', 'fin/0/plan', ...]: what it holds
        body = rec["body/state"]
        body.t                             # the messages' own times (s), a float64 array
        body["velocity.x"]                 # a column, named by its MCAP message path
        body.units["velocity.x"]           # 'm/s' (symbols pint parses)
        df = body.to_pandas()              # needs pandas; df.attrs["units"] holds the units

``open`` takes the path of a session file (any part of a split session: every part beside
it is read, in order) and reads a channel when it is first asked for. Columns are those of
the CSV export (``ucat-console sessions export``): ``log_time_ns`` (the file's UNIX
nanoseconds), then each field by its message path (``position.x``, ``per_fin[2]``; a
quaternion x, y, z, w). Numbers are float64 (NaN where a value was not finite or an
optional part is absent), integers int64 (Python integers where they may exceed 2^63:
planner seeds), flags bool, text, lists and JSON objects Python objects. Units come from
the message definitions, one per column ("" for text, flags and counts, "1" for a
dimensionless number).

The derived Foxglove channels (transforms, scene, log) are left out: they repeat
``body/state``, the fin states and the events.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from ucat_console.backend.sessions import images
from ucat_console.backend.sessions.export import TIME_COLUMN, column_specs
from ucat_console.backend.sessions.reader import SessionParts, open_session
from ucat_console.backend.sessions.schema import BOOL, FLOAT, FLOATS, INT, SEQ, field_specs
from ucat_console.telemetry.channels import CHANNELS

__all__ = ["Channel", "Recording", "open"]


@dataclass(frozen=True)
class Channel:
    """One channel's messages as columns (equal-length arrays, in log-time order)."""

    name: str
    columns: dict[str, np.ndarray]
    units: dict[str, str]
    descriptions: dict[str, str] = field(repr=False)

    def __getitem__(self, column: str) -> np.ndarray:
        try:
            return self.columns[column]
        except KeyError:
            raise KeyError(f"{self.name}: no column {column!r} (columns: {', '.join(self.columns)})") from None

    def __len__(self) -> int:
        return len(self.columns[TIME_COLUMN])

    @property
    def t(self) -> np.ndarray:
        """The messages' own times (s, on the stream's clock)."""
        return self.columns["t"]

    @property
    def log_time_ns(self) -> np.ndarray:
        return self.columns[TIME_COLUMN]

    def to_pandas(self) -> Any:
        """The columns as a pandas DataFrame (``attrs["units"]``: the unit of each column)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError(f"{self.name}: to_pandas needs pandas (pip install pandas); "
                              "the columns are there as NumPy arrays without it") from None
        frame = pd.DataFrame(dict(self.columns))
        frame.attrs["units"] = dict(self.units)
        frame.attrs["channel"] = self.name
        return frame


class Recording:
    """An open session (``close()`` or a context manager); ``rec[channel]`` reads one."""

    def __init__(self, parts: SessionParts) -> None:
        self._parts = parts
        self._cache: dict[str, Channel] = {}
        self.path: Path = parts.path
        self.paths: tuple[Path, ...] = parts.paths
        self.session_id: str = parts.session_id
        self.metadata: dict[str, dict[str, str]] = dict(parts.parts[0].metadata)

    @property
    def channels(self) -> list[str]:
        """The telemetry channels that hold messages, in the definitions' order (columns of
        numbers: the camera's pictures, ``camera/image``, are read with the session reader)."""
        counts = self._parts.message_counts()
        return [c for c in CHANNELS if counts.get(c, 0) > 0 and not images.is_image(CHANNELS[c])]

    def __getitem__(self, channel: str) -> Channel:
        if channel not in self._cache:
            if channel not in CHANNELS:
                raise KeyError(f"{channel!r} is not a telemetry channel (channels: {', '.join(CHANNELS)})")
            if images.is_image(CHANNELS[channel]):
                raise KeyError(f"{channel!r} holds pictures, not columns: read its frames with "
                               "ucat_console.backend.sessions.reader.SessionReader.records")
            self._cache[channel] = _read(self._parts, channel)
        return self._cache[channel]

    def __iter__(self) -> Iterator[str]:
        return iter(self.channels)

    def close(self) -> None:
        self._parts.close()

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def open(path: str | Path) -> Recording:  # noqa: A001 (the module's one entry: sessions.open)
    """Open the session file at ``path`` (and the other parts of its session beside it)."""
    p = Path(path).expanduser().resolve()
    if not p.is_file():
        raise ValueError(f"{path}: no such session file")
    return Recording(open_session(p, confined=False))


def _read(parts: SessionParts, channel: str) -> Channel:
    cls = CHANNELS[channel]
    specs = column_specs(cls)
    where: list[tuple[str, Any, int]] = []  # (column, field spec, index in a tuple)
    by_path = {}
    for s in field_specs(cls):
        for i, p in enumerate(s.paths()):
            by_path[p] = (s, i)
    for col in specs[1:]:
        s, i = by_path[col["name"]]
        where.append((col["name"], s, i))
    times: list[int] = []
    values: list[list[Any]] = [[] for _ in where]
    for rec in parts.records([channel]):
        times.append(rec.log_time_ns)
        msg = rec.message
        for k, (_, s, i) in enumerate(where):
            v = getattr(msg, s.name)
            if s.kind == FLOATS:
                v = math.nan if v is None else v[i]
            values[k].append(v)
    columns = {TIME_COLUMN: np.array(times, dtype=np.int64)}
    for (name, s, _), vs in zip(where, values):
        columns[name] = _array(s, vs)
    for a in columns.values():
        a.setflags(write=False)
    return Channel(channel, columns, {c["name"]: c.get("unit", "") for c in specs},
                   {c["name"]: c["description"] for c in specs})


def _array(spec: Any, values: list[Any]) -> np.ndarray:
    kind = spec.kind
    if kind in (FLOAT, FLOATS):
        return np.array(values, dtype=np.float64)
    if not spec.optional and kind == INT and not spec.wide:
        return np.array(values, dtype=np.int64)
    if not spec.optional and kind == BOOL:
        return np.array(values, dtype=bool)
    out = np.empty(len(values), dtype=object)  # text, lists, JSON, wide or optional values
    for j, v in enumerate(values):
        out[j] = list(v) if kind == SEQ and v is not None else v
    return out
