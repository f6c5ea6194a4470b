"""Reading session files: messages decoded back to the telemetry dataclasses.

:class:`SessionReader` opens one session file (part) and refuses, with a ValueError naming
the problem: a path outside the sessions directory, a file that is not MCAP, a truncated file
(no summary: ``ucat-console sessions repair``), a corrupted or a foreign one (not our channels).

:class:`SessionParts` opens every part of one session (``<id>_001.mcap``, ``_002`` ...)
and reads them as one recording with the same interface: records in time order across
part boundaries, the state at any time, the events of every part. It refuses a gap in
the part numbers and parts that disagree on the session or its ``epoch_offset``;
:func:`open_session` opens a session by id or by any of its part files.

Times are seconds on the recorded stream's clock (the messages' ``t``; the file's
``epoch_offset`` converts them to its nanoseconds), ranges half-open ``[start, end)``.

The reader is a typed view: :mod:`.mcap_read` reads the file (beside the writer), :mod:`.files`
finds a session's parts; here the messages are decoded, and a part and a whole session offer
one interface (records in time order, ``state_at``, events).
"""

from __future__ import annotations

import bisect
import heapq
import math
import os
import threading
from array import array
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Iterable, Iterator, Self, Sequence

from mcap.records import Channel, Message, Schema
from mcap.summary import Summary

from ucat_console.backend.sessions import codec, files, foxglove, images, legacy
from ucat_console.backend.sessions.limits import MemoryBudget
from ucat_console.backend.sessions.mcap_read import MAGIC, BudgetHolder, McapFile
from ucat_console.backend.sessions.schema import (
    MESSAGE_ENCODING,
    NONFINITE,
    SCHEMA_ENCODING,
    field_specs,
    schema_encoding,
    schema_name,
)
from ucat_console.telemetry.channels import CHANNELS, EVENTS
from ucat_console.telemetry.events import LEVELS, Event

#: the message decoder of each schema encoding (schema.schema_encoding)
_DECODERS = {1: legacy.decode, 2: codec.decode, images.ENCODING: images.decode}


@dataclass(frozen=True)
class Record:
    """One decoded message with its file time."""

    channel: str
    log_time_ns: int
    message: Any


def _check_schema(topic: str, schema: Schema | None, channel: Channel, path: Path) -> int:
    """The encoding of ``channel`` (0 for a derived Foxglove channel); ValueError unless it
    is one of ours with our schema."""
    if topic in CHANNELS:
        cls = CHANNELS[topic]
        want = schema_name(cls)
        if schema is None or schema.name != want or schema.encoding != SCHEMA_ENCODING:
            got = "no schema" if schema is None else f"schema {codec.short(schema.name)} ({codec.short(schema.encoding)})"
            raise ValueError(f"{path}: not a session file: channel {codec.short(topic)} has {got}, "
                             f"expected {want!r} (jsonschema)")
        if channel.message_encoding != MESSAGE_ENCODING:
            raise ValueError(f"{path}: not a session file: channel {codec.short(topic)} is encoded "
                             f"{codec.short(channel.message_encoding)}, expected 'json'")
        try:
            doc = codec.load_json(schema.data, "schema")
            props = set(doc["properties"])
        except (ValueError, KeyError, TypeError):
            raise ValueError(
                f"{path}: channel {codec.short(topic)}: schema is not a JSON Schema object"
            ) from None
        try:
            encoding = schema_encoding(doc)
        except ValueError as e:
            raise ValueError(f"{path}: channel {codec.short(topic)}: {e}") from None
        fields = {s.name for s in field_specs(cls)} | {NONFINITE}
        former = codec.FORMER_FIELDS.get(cls.__name__)
        if former is not None:  # a field under its former name (the decoder converts it)
            fields.add(former[0])
        if not props <= fields:
            raise ValueError(f"{path}: channel {codec.short(topic)}: schema fields "
                             f"{codec.short(sorted(props - fields))} are not fields of {cls.__name__}")
        return encoding
    name = foxglove.DERIVED_TOPICS.get(topic) or foxglove.LEGACY_TOPICS.get(topic)
    if name is not None:
        if schema is None or schema.name != name:
            raise ValueError(f"{path}: not a session file: channel {codec.short(topic)} is not {name}")
        return 0
    raise ValueError(f"{path}: not a session file: foreign channel {codec.short(topic)}"
                     + (f" (schema {codec.short(schema.name)})" if schema is not None else ""))


@dataclass(frozen=True)
class EventIndex:
    """The events of a recording as two compact columns: file time (ns) and level (an index
    into :data:`~ucat_console.telemetry.events.LEVELS`)."""

    COST = 9  # bytes per event
    times_ns: array[int]
    levels: bytes

    def at_levels(self, levels: Iterable[str] | None) -> list[int]:
        """The times of the events of ``levels`` (None: every event)."""
        if levels is None:
            return list(self.times_ns)
        want = {LEVELS.index(x) for x in levels if x in LEVELS}
        return [t for t, lv in zip(self.times_ns, self.levels) if lv in want]


_INDEX_LOCK = threading.Lock()


class _Recording(BudgetHolder):
    """What a recording offers on top of its ``records`` and ``state_records_at_ns``: times
    in stream seconds, metadata by name, messages, state and events (shared by one part
    file and a whole session)."""

    path: Path
    metadata: dict[str, dict[str, str]]
    epoch_offset: float
    message_count: int
    start_ns: int
    end_ns: int
    _event_index: EventIndex | None = None

    def close(self) -> None:
        raise NotImplementedError

    def records(
        self,
        channels: Iterable[str] | None = None,
        start: float | None = None,
        end: float | None = None,
        *,
        start_ns: int | None = None,
        end_ns: int | None = None,
        reverse: bool = False,
    ) -> Iterator[Record]:
        """Decoded messages in time order (``reverse``: latest first) within
        ``[start, end)`` (stream seconds) or ``[start_ns, end_ns)`` (file nanoseconds)."""
        lo = start_ns if start is None else self.to_ns(start)
        hi = end_ns if end is None else self.to_ns(end)
        yield from self._records_ns(self._topics(channels), lo, hi, reverse)

    def _topics(self, channels: Iterable[str] | None) -> list[str] | None:
        raise NotImplementedError

    def _records_ns(self, topics: list[str] | None, lo: int | None, hi: int | None,
                    reverse: bool) -> Iterator[Record]:
        raise NotImplementedError

    def state_records_at_ns(self, ns: int, channels: Iterable[str] | None = None) -> dict[str, Record]:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    @property
    def start(self) -> float:
        """Time of the first message (stream seconds)."""
        return self.from_ns(self.start_ns)

    @property
    def end(self) -> float:
        """Time of the last message (stream seconds)."""
        return self.from_ns(self.end_ns)

    @property
    def duration(self) -> float:
        """From the first message to the last (s)."""
        return (self.end_ns - self.start_ns) * 1e-9 if self.message_count else 0.0

    @property
    def notes(self) -> str:
        return self.metadata.get(files.META_NOTES, {}).get("text", "")

    @property
    def config_toml(self) -> str:
        return self.metadata.get(files.META_CONFIG, {}).get("toml", "")

    @property
    def weights(self) -> dict[str, float]:
        out = {}
        for k, v in self.metadata.get(files.META_WEIGHTS, {}).items():
            try:
                out[k] = float(v)
            except ValueError:
                raise ValueError(
                    f"{self.path}: weights metadata: {codec.short(k)}={codec.short(v)} is not a number"
                ) from None
        return out

    @property
    def version(self) -> str:
        return self.metadata.get(files.META_VERSION, {}).get("ucat_console", "")

    def to_ns(self, t: float) -> int:
        return codec.to_ns(t, self.epoch_offset)

    def from_ns(self, ns: int) -> float:
        return codec.from_ns(ns, self.epoch_offset)

    def messages(
        self,
        channels: Iterable[str] | None = None,
        start: float | None = None,
        end: float | None = None,
    ) -> Iterator[tuple[str, Any]]:
        """``(channel, message)`` in time order within ``[start, end)``."""
        for r in self.records(channels, start, end):
            yield r.channel, r.message

    def state_at(self, t: float, channels: Iterable[str] | None = None) -> dict[str, Any]:
        """The latest message of each channel at or before ``t`` (channels with none are
        left out)."""
        return {c: r.message for c, r in self.state_records_at_ns(self.to_ns(t), channels).items()}

    def events(self, start: float | None = None, end: float | None = None) -> list[Event]:
        """The recorded events within ``[start, end)``, in time order."""
        return [m for _, m in self.messages([EVENTS], start, end)]

    def event_index(self) -> EventIndex:
        """The time and level of every recorded event, in time order: read once (each event
        decoded and let go), then kept while the file is open, within the memory budget."""
        with _INDEX_LOCK:
            if self._event_index is None:
                times: array[int] = array("q")
                levels = bytearray()
                for r in self.records([EVENTS]):
                    if len(times) % 4096 == 0:
                        self._hold(4096 * EventIndex.COST, "its event index")
                    times.append(r.log_time_ns)
                    levels.append(LEVELS.index(r.message.level))
                self._event_index = EventIndex(times, bytes(levels))
            return self._event_index


class SessionReader(McapFile, _Recording):
    """One session file, opened for reading (use as a context manager or ``close()``).

    Read by :class:`~.mcap_read.McapFile` within its ``budget``'s limits (default: a budget
    of its own), with ``os.pread``: one reader may serve several threads (the pages sharing
    it, :mod:`.shared`). Its channels must be ours; its messages are decoded to the
    telemetry dataclasses.
    """

    def __init__(self, path: str | Path, directory: str | Path | None = None, *, confined: bool = True,
                 budget: MemoryBudget | None = None) -> None:
        self.path = files.session_path(path, directory, confined=confined)
        self.budget = budget if budget is not None else MemoryBudget()
        p = self.path
        if not p.is_file():
            raise ValueError(f"{path}: no such session file")
        self._file: IO[bytes] = open(p, "rb")
        try:
            self._open()
        except BaseException:
            self.close()
            raise

    def _open(self) -> None:
        p = self.path
        self._fd = self._file.fileno()
        self._size = os.fstat(self._fd).st_size
        if os.pread(self._fd, len(MAGIC), 0) != MAGIC:
            raise ValueError(f"{p}: not an MCAP file (it does not start with the MCAP magic)")
        summary = self._read_summary()
        self._summary: Summary = summary
        channels = summary.channels
        if not channels:
            raise ValueError(f"{p}: not a session file: it has no channels")
        self._topic_ids: dict[str, int] = {}
        self._decoders: dict[str, Any] = {}
        for cid, ch in channels.items():
            schema = summary.schemas.get(ch.schema_id) if ch.schema_id else None
            unknown_sensor = ch.topic.startswith("sensors/") and ch.topic not in CHANNELS  # not registered here: unread
            encoding = 0 if unknown_sensor else images.check_schema(ch.topic, schema, ch, p) or _check_schema(ch.topic, schema, ch, p)
            self._topic_ids[ch.topic] = cid
            if encoding:
                self._decoders[ch.topic] = _DECODERS[encoding]
        if not any(t in CHANNELS for t in self._topic_ids):
            raise ValueError(
                f"{p}: not a session file: none of its channels is a telemetry channel"
            )
        self._check_chunk_indexes(summary)
        self.metadata: dict[str, dict[str, str]] = self._read_metadata(summary)
        session = self.metadata.get(files.META_SESSION, {})
        try:
            self.epoch_offset = float(session.get("epoch_offset", "0.0"))
            self.part = int(session.get("part", "1"))
        except ValueError:
            raise ValueError(f"{p}: bad session metadata {codec.short(session)}") from None
        if not math.isfinite(self.epoch_offset):
            raise ValueError(f"{p}: bad session metadata: epoch_offset {self.epoch_offset!r}")
        parsed = files.parse_part_name(p)
        self.session_id = session.get("id") or (parsed[0] if parsed else p.stem)
        if len(self.session_id) > 128 or not self.session_id.isprintable():
            raise ValueError(f"{p}: bad session metadata: id {codec.short(self.session_id)}")
        stats = summary.statistics
        assert stats is not None
        self.message_count = sum(
            n for cid, n in stats.channel_message_counts.items()
            if cid in channels and channels[cid].topic in CHANNELS
        )
        self.start_ns = stats.message_start_time
        self.end_ns = stats.message_end_time

    # ------------------------------------------------------------------ properties
    @property
    def channels(self) -> list[str]:
        """Telemetry channels registered in the file."""
        return [t for t in self._topic_ids if t in CHANNELS]

    def message_counts(self) -> dict[str, int]:
        stats = self._summary.statistics
        assert stats is not None
        counts = {t: 0 for t in self.channels}
        for cid, n in stats.channel_message_counts.items():
            topic = self._summary.channels[cid].topic
            if topic in counts:
                counts[topic] = n
        return counts

    # ------------------------------------------------------------------ messages
    def _topics(self, channels: Iterable[str] | None) -> list[str]:
        if channels is None:
            return self.channels
        out = []
        for c in channels:
            if c not in CHANNELS:
                raise ValueError(f"unknown telemetry channel {c!r}")
            if c in self._topic_ids:
                out.append(c)
        return out

    def _decode(self, channel: Channel, message: Message) -> Record:
        cls = CHANNELS[channel.topic]
        try:
            msg = self._decoders[channel.topic](cls, message.data)
        except ValueError as e:
            raise ValueError(
                f"{self.path}: channel {channel.topic!r}, message at {message.log_time} ns: {e}"
            ) from None
        return Record(channel.topic, message.log_time, msg)

    def _records_ns(self, topics: list[str] | None, lo: int | None, hi: int | None,
                    reverse: bool) -> Iterator[Record]:
        for channel, message in self._iter(topics, lo, hi, reverse):
            yield self._decode(channel, message)

    def state_records_at_ns(
        self, ns: int, channels: Iterable[str] | None = None
    ) -> dict[str, Record]:
        """:meth:`state_at` for a file time ``ns``, with the messages' file times.

        Guided by the chunk index: walking back from the chunk that holds ``ns``, each
        chunk that holds a channel still missing is read once, in file order, over
        ``[chunk start, ns]`` for those channels, keeping each channel's latest message
        (a chunk overlapping that range is read with it, so out-of-order writes are
        covered). A typical call decodes the chunk at ``ns`` plus one for each rare
        channel (events): a few milliseconds at 64 KiB chunks, where a ``reverse=True``
        read would pass every message of those chunks through its ordering heap.
        """
        topics = self._topics(channels)
        ids = {t: self._topic_ids[t] for t in topics}
        pending = set(self._present_before(topics, ns))
        latest: dict[str, tuple[Channel, Message]] = {}
        chunks, starts = self._chunks_by_start()
        i = bisect.bisect_right(starts, ns) - 1
        while pending and i >= 0:
            ci = chunks[i]
            i -= 1
            offsets = ci.message_index_offsets
            want = [t for t in pending if not offsets or ids[t] in offsets]
            if not want:
                continue
            for channel, message in self._iter(
                want, ci.message_start_time, ns + 1, ordered=False
            ):
                best = latest.get(channel.topic)
                if best is None or message.log_time >= best[1].log_time:
                    latest[channel.topic] = (channel, message)
            pending.difference_update(latest)
        return {c: self._decode(*latest[c]) for c in topics if c in latest}


# ---------------------------------------------------------------------- whole sessions
def _check_parts(readers: Sequence[SessionReader], session_id: str | None) -> None:
    """ValueError naming the part that does not belong with the first: another session id
    or part number in its metadata than in its name, or another ``epoch_offset``."""
    first = readers[0]
    for n, r in enumerate(readers, 1):
        meta = r.metadata.get(files.META_SESSION, {})
        if session_id is not None and meta.get("id", session_id) != session_id:
            raise ValueError(f"{r.path}: its metadata names session {codec.short(meta['id'])}, "
                             f"not {session_id!r}")
        if session_id is not None and "part" in meta and r.part != n:
            raise ValueError(f"{r.path}: its metadata names part {r.part}, not {n}")
        if r.epoch_offset != first.epoch_offset:
            raise ValueError(
                f"{r.path}: epoch_offset {r.epoch_offset!r} differs from {first.path.name}'s "
                f"{first.epoch_offset!r}; the parts of one session share their clock"
            )


def _by_time(rec: Record) -> int:
    return rec.log_time_ns


class SessionParts(_Recording):
    """Every part of one session, read as one recording (``close()`` or a context manager).

    Opened from a session id (its parts in the sessions ``directory``) or from the path of
    any one part (its parts beside it); a file whose name is not a part name is read
    alone, as the session named by its file name (whatever its metadata says). A named file
    must lie in the sessions directory unless ``confined=False`` (the command line: a file
    the user named is read wherever it is; a page never opens one so). Holds one
    :class:`SessionReader` per part in part order (``parts``) and offers their interface
    over the whole session, so the player, the review panel, the export and counterfactual
    replay read a split session as one file:

    * times: ``start_ns``/``end_ns`` span every part; the parts share the session's
      ``epoch_offset``, so ``to_ns``/``from_ns`` are those of any part;
    * ``records``/``messages``: every part's messages in time order (the parts follow each
      other in time; parts that overlap are merged), at equal times the earlier part first;
    * ``state_at``/``state_records_at_ns``: the latest message of each channel at or before
      a time, from the part holding that time and, for channels with no message there yet,
      from the parts before it;
    * ``metadata``: the first part's records with the latest part's ``notes``; the
      configuration, weights and version are the first part's.

    ``path`` is the first part's file (its directory holds the review markers, which are
    per session); ``paths`` every part's.
    """

    def __init__(self, session: str | Path, directory: str | Path | None = None, *,
                 confined: bool = True, budget: MemoryBudget | None = None) -> None:
        root = files.sessions_dir(directory)
        sid, paths = files.session_paths(session, root, confined)
        self.budget = budget if budget is not None else MemoryBudget()
        readers: list[SessionReader] = []
        try:
            for path in paths:  # a truncated part: TruncatedSessionError naming it
                readers.append(SessionReader(path, root, confined=confined, budget=self.budget))
            _check_parts(readers, sid)
        except BaseException:
            for r in readers:
                r.close()
            raise
        self.parts: tuple[SessionReader, ...] = tuple(readers)
        first = readers[0]
        self.session_id: str = sid if sid is not None else first.path.name  # by name, not metadata
        self.path: Path = first.path
        self.paths: tuple[Path, ...] = tuple(r.path for r in readers)
        self.epoch_offset: float = first.epoch_offset
        self._filled = [r for r in readers if r.message_count > 0]
        self.message_count: int = sum(r.message_count for r in readers)
        self.start_ns: int = min((r.start_ns for r in self._filled), default=first.start_ns)
        self.end_ns: int = max((r.end_ns for r in self._filled), default=first.end_ns)

    # ------------------------------------------------------------------ properties
    def close(self) -> None:
        for r in self.parts:
            r.close()
        self._let_go()

    @property
    def directory(self) -> Path:
        """The directory holding the parts (and the session's review markers)."""
        return self.path.parent

    @property
    def metadata(self) -> dict[str, dict[str, str]]:
        """The first part's metadata records with the latest part's notes."""
        out = {name: dict(data) for name, data in self.parts[0].metadata.items()}
        notes = self.parts[-1].metadata.get(files.META_NOTES)
        if notes is not None:
            out[files.META_NOTES] = dict(notes)
        return out

    @property
    def channels(self) -> list[str]:
        """Telemetry channels registered in any part, in order of first registration."""
        return list(dict.fromkeys(c for r in self.parts for c in r.channels))

    def message_counts(self) -> dict[str, int]:
        """Messages per channel over every part."""
        counts = {c: 0 for c in self.channels}
        for r in self.parts:
            for c, n in r.message_counts().items():
                counts[c] += n
        return counts

    def part_at_ns(self, ns: int) -> int:
        """The part number (from 1) holding file time ``ns``: the last part with a message
        at or before it (1 before the first message)."""
        number = 1
        for n, r in enumerate(self.parts, 1):
            if r.message_count and r.start_ns <= ns:
                number = n
        return number

    # ------------------------------------------------------------------ messages
    def _topics(self, channels: Iterable[str] | None) -> list[str] | None:
        if channels is None:
            return None
        out = list(channels)
        for c in out:
            if c not in CHANNELS:
                raise ValueError(f"unknown telemetry channel {c!r}")
        return out

    def _runs(self, lo: int | None, hi: int | None) -> list[list[SessionReader]]:
        """The parts with messages in ``[lo, hi)``, in runs that follow each other in time:
        a run's parts overlap, and every message of a run is at or after the previous
        run's. Parts in a run are in part order."""
        parts = [
            r for r in self._filled
            if (hi is None or r.start_ns < hi) and (lo is None or r.end_ns >= lo)
        ]
        order = sorted(range(len(parts)), key=lambda i: (parts[i].start_ns, i))
        runs: list[list[int]] = []
        run_end = 0
        for i in order:
            r = parts[i]
            if runs and r.start_ns < run_end:
                runs[-1].append(i)
                run_end = max(run_end, r.end_ns)
            else:
                runs.append([i])
                run_end = r.end_ns
        return [[parts[i] for i in sorted(run)] for run in runs]

    def _records_ns(self, topics: list[str] | None, lo: int | None, hi: int | None,
                    reverse: bool) -> Iterator[Record]:
        """Every part's records, merged in time order."""
        runs = self._runs(lo, hi)
        for run in reversed(runs) if reverse else runs:
            its = [
                r.records(topics, start_ns=lo, end_ns=hi, reverse=reverse)
                for r in (reversed(run) if reverse else run)
            ]
            if len(its) == 1:
                yield from its[0]
            else:
                yield from heapq.merge(*its, key=_by_time, reverse=reverse)

    def state_records_at_ns(
        self, ns: int, channels: Iterable[str] | None = None
    ) -> dict[str, Record]:
        """:meth:`state_at` for a file time ``ns``, with the messages' file times.

        The part holding ``ns`` is asked first; the parts before it only for the channels
        it has no message of by then (or, where parts overlap, one older than their end).
        At equal times the later part's message is the latest, as in :meth:`records`.
        """
        topics = self._topics(channels)
        wanted = self.channels if topics is None else list(dict.fromkeys(topics))
        latest: dict[str, Record] = {}
        for r in reversed(self._filled):
            if r.start_ns > ns:
                continue
            ask = [c for c in wanted if c not in latest or latest[c].log_time_ns < r.end_ns]
            if not ask:
                continue
            for c, rec in r.state_records_at_ns(ns, ask).items():
                if c not in latest or rec.log_time_ns > latest[c].log_time_ns:
                    latest[c] = rec
        return {c: latest[c] for c in wanted if c in latest}


#: what the player, the review panel, the export and counterfactual replay read from
SessionSource = SessionReader | SessionParts


def open_session(session: str | Path, directory: str | Path | None = None, *,
                 confined: bool = True, budget: MemoryBudget | None = None) -> SessionParts:
    """Open a whole session inside ``directory`` (default: the project's ``sessions/``).

    ``session``: a session id, or the path or file name of any one of its parts (every
    part is opened); a file whose name is not a part name is opened alone. A one-part
    session reads exactly as its file does with :class:`SessionReader`. ``confined=False``:
    a named file is read wherever it is (a path the user typed, :func:`files.session_path`).
    ``budget``: the memory budget it reads within (default: one of its own).
    """
    return SessionParts(session, directory, confined=confined, budget=budget)
