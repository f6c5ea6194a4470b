"""Reading session files: messages decoded back to the telemetry dataclasses.

:class:`SessionReader` opens one session file (part) and refuses, with a ValueError naming
the problem: a path outside the sessions directory, a file that is not MCAP, a truncated
file (no summary: run ``ucat-console sessions repair``), a corrupted file, and a foreign
MCAP file (a channel or schema that is not ours).

:class:`SessionParts` opens every part of one session (``<id>_001.mcap``, ``_002`` ...)
and reads them as one recording with the same interface: records in time order across
part boundaries, the state at any time, the events of every part. It refuses a gap in
the part numbers and parts that disagree on the session or its ``epoch_offset``;
:func:`open_session` opens a session by id or by any of its part files.

Times given to and returned by the reader are seconds on the recorded stream's clock (the
messages' ``t``); the file's ``epoch_offset`` converts them to the file's nanoseconds.
Time ranges are half-open, ``[start, end)``, as mcap's ``starting_at``/``ending_before``.

Over 500 lines because the one part file and the whole session are one interface with one
base (records in time order, ``state_at``, events, the refusals above): split, the checks
a part and a session share would be read in two places.
"""

from __future__ import annotations

import bisect
import heapq
import io
import logging
import math
import os
import struct
import threading
import zlib
from array import array
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Iterable, Iterator, Self, Sequence

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import (
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    Footer,
    Message,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
)
from mcap.stream_reader import StreamReader
from mcap.summary import Summary

from ucat_console.backend.sessions import codec, files, foxglove, legacy, limits
from ucat_console.backend.sessions.schema import (
    MESSAGE_ENCODING,
    NONFINITE,
    SCHEMA_ENCODING,
    field_specs,
    schema_encoding,
    schema_name,
)

#: the message decoder of each schema encoding (schema.schema_encoding)
_DECODERS = {1: legacy.decode, 2: codec.decode}
from ucat_console.telemetry.channels import CHANNELS, EVENTS
from ucat_console.telemetry.events import LEVELS, Event

log = logging.getLogger(__name__)

MAGIC = b"\x89MCAP0\r\n"
FOOTER_SIZE = 1 + 8 + 8 + 8 + 4  # opcode, length, summary start, summary offset start, CRC
_RECORD_HEAD = struct.Struct("<BQ")  # opcode, length
_MESSAGE_FIELDS = struct.Struct("<HIQQ")  # channel, sequence, log time, publish time
#: bytes of the memory budget per byte of a summary section (its records as Python objects,
#: measured with tracemalloc: about 6 on a recorded session)
SUMMARY_COST = 8
#: bytes of the memory budget per message held besides its data (the record object, its
#: place in the ordering heap; measured with tracemalloc: about 200)
MESSAGE_COST = 400


def record_limit() -> int:
    """The largest record read whole: a chunk within the limit, compressed (zstd and lz4
    add a little to data that does not compress), with its header."""
    cap = limits.limits().max_chunk
    return cap + cap // 64 + 4096


def _error(e: BaseException) -> str:
    text = str(e)
    return f"{type(e).__name__}: {text if len(text) <= 200 else text[:197] + '...'}"


def _by_offset(ci: ChunkIndex) -> int:
    return ci.chunk_start_offset


def _chunk_data(body: bytes, ci: ChunkIndex) -> bytes:
    """The decompressed records of the chunk record ``body`` (read where ``ci`` puts it);
    ValueError unless it is the chunk ``ci`` describes and decompresses as it declares."""
    if len(body) != ci.chunk_length:
        raise ValueError("the file ends inside it")
    opcode, length = _RECORD_HEAD.unpack_from(body)
    if opcode != Opcode.CHUNK or _RECORD_HEAD.size + length != len(body):
        raise ValueError(f"there is no chunk record of {ci.chunk_length} bytes there")
    try:
        chunk = Chunk.read(ReadDataStream(io.BytesIO(body[_RECORD_HEAD.size:])))
    except Exception as e:
        raise ValueError(f"unreadable chunk header ({_error(e)})") from None
    if (chunk.uncompressed_size, chunk.compression, len(chunk.data)) != (
            ci.uncompressed_size, ci.compression, ci.compressed_size):
        raise ValueError(
            f"it is not the chunk its index describes ({codec.short(chunk.compression, 12)}, {len(chunk.data)} -> "
            f"{chunk.uncompressed_size} bytes; the index: {codec.short(ci.compression, 12)}, {ci.compressed_size} -> "
            f"{ci.uncompressed_size} bytes)")
    return decompressed(chunk)


def decompressed(chunk: Chunk) -> bytes:
    """A chunk's records, decompressed within the chunk limit, CRC checked (ValueError)."""
    cap = limits.limits().max_chunk
    if chunk.uncompressed_size > cap:
        raise ValueError(f"it decompresses to {chunk.uncompressed_size} bytes, over the limit of "
                         f"{cap} (review.max_chunk)")
    data = limits.decompress(chunk.compression, chunk.data, chunk.uncompressed_size)
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ValueError("its CRC does not match its data")
    return data


class TruncatedSessionError(ValueError):
    """The file has no readable summary (a killed recorder): ``repair`` recovers it."""


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


class _Recording:
    """What a recording offers on top of its ``records`` and ``state_records_at_ns``: times
    in stream seconds, metadata by name, messages, state and events (shared by one part
    file and a whole session)."""

    path: Path
    metadata: dict[str, dict[str, str]]
    epoch_offset: float
    message_count: int
    start_ns: int
    end_ns: int
    _held = 0  # bytes of the memory budget held while open (summary, metadata, event index)
    _event_index: EventIndex | None = None

    def close(self) -> None:
        raise NotImplementedError

    def _hold(self, n: int, what: str) -> None:
        limits.budget().reserve(n, f"{self.path}: {what}")
        self._held += n

    def _let_go(self) -> None:
        held, self._held = self._held, 0
        limits.budget().release(held)

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


class SessionReader(_Recording):
    """One session file, opened for reading (use as a context manager or ``close()``).

    Within the limits of :mod:`~ucat_console.backend.sessions.limits`: the summary, the
    metadata and each chunk are read with mcap's record reader (``StreamReader``, chunks
    emitted whole: nothing is decompressed behind the limits' back), each chunk checked
    against its index and decompressed here no further than it declares. Reads use
    ``os.pread``: one reader may serve several threads (the pages sharing it, :mod:`.shared`).
    """

    def __init__(self, path: str | Path, directory: str | Path | None = None, *, confined: bool = True) -> None:
        self.path = files.session_path(path, directory, confined=confined)
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
            encoding = _check_schema(ch.topic, schema, ch, p)
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

    def _records_at(self, offset: int) -> Iterator[Any]:
        """mcap's record reader from ``offset`` (chunks emitted whole, records within the
        limits' largest record)."""
        self._file.seek(offset)
        return StreamReader(self._file, skip_magic=True, emit_chunks=True,
                            record_size_limit=record_limit()).records

    def _read_summary(self) -> Summary:
        """The summary section (TruncatedSessionError when there is none): its records, read
        within the memory budget, and nothing but summary records."""
        p = self.path
        tail = FOOTER_SIZE + len(MAGIC)
        end = os.pread(self._fd, tail, self._size - tail) if self._size >= len(MAGIC) + tail else b""
        if len(end) != tail or end[-len(MAGIC):] != MAGIC or end[0] != Opcode.FOOTER:
            raise TruncatedSessionError(
                f"{p}: truncated or corrupted (no footer at its end); "
                "`ucat-console sessions repair` recovers its complete records"
            )
        summary_start = int.from_bytes(end[9:17], "little")
        if summary_start == 0:
            raise TruncatedSessionError(
                f"{p}: has no summary section; `ucat-console sessions repair` "
                "rewrites it fully indexed"
            )
        if not len(MAGIC) <= summary_start <= self._size - tail:
            raise ValueError(f"{p}: corrupted data: its footer puts the summary at byte {summary_start} "
                             f"of {self._size}")
        self._hold(SUMMARY_COST * (self._size - tail - summary_start), "its summary")
        summary = Summary()
        try:
            for rec in self._records_at(summary_start):
                if isinstance(rec, Footer):
                    break
                if isinstance(rec, Statistics):
                    summary.statistics = rec
                elif isinstance(rec, Schema):
                    summary.schemas[rec.id] = rec
                elif isinstance(rec, Channel):
                    summary.channels[rec.id] = rec
                elif isinstance(rec, ChunkIndex):
                    summary.chunk_indexes.append(rec)
                elif isinstance(rec, MetadataIndex):
                    summary.metadata_indexes.append(rec)
                elif isinstance(rec, AttachmentIndex):
                    summary.attachment_indexes.append(rec)
                elif isinstance(rec, (Chunk, Message)):
                    raise McapError(f"a {type(rec).__name__} record in the summary section")
        except ValueError:
            raise
        except Exception as e:
            raise TruncatedSessionError(
                f"{p}: truncated or corrupted (no readable summary: {_error(e)}); "
                "`ucat-console sessions repair` recovers its complete records"
            ) from None
        if summary.statistics is None:
            raise TruncatedSessionError(
                f"{p}: has no summary section; `ucat-console sessions repair` "
                "rewrites it fully indexed"
            )
        return summary

    def _check_chunk_indexes(self, summary: Summary) -> None:
        """Every chunk the index lists lies within the file and within the chunk limit."""
        p, cap, stats = self.path, limits.limits().max_chunk, summary.statistics
        assert stats is not None
        if stats.message_count and not summary.chunk_indexes:
            raise ValueError(f"{p}: has messages but no chunk index; `ucat-console sessions repair "
                             "--force` rewrites it indexed")
        for ci in summary.chunk_indexes:
            where = f"{p}: the chunk at byte {ci.chunk_start_offset}"
            if ci.uncompressed_size > cap:
                raise ValueError(f"{where} decompresses to {ci.uncompressed_size} bytes, over the "
                                 f"limit of {cap} (review.max_chunk)")
            if not (len(MAGIC) <= ci.chunk_start_offset
                    and ci.chunk_start_offset + ci.chunk_length <= self._size
                    and ci.chunk_length <= record_limit()):
                raise ValueError(f"{where}: corrupted index: {ci.chunk_length} bytes at byte "
                                 f"{ci.chunk_start_offset} of a {self._size}-byte file")

    def _read_metadata(self, summary: Summary) -> dict[str, dict[str, str]]:
        """The metadata records by name (a later record replaces an earlier one)."""
        out: dict[str, dict[str, str]] = {}
        self._hold(2 * sum(mi.length for mi in summary.metadata_indexes), "its metadata")
        try:
            for mi in summary.metadata_indexes:
                if not len(MAGIC) <= mi.offset < self._size:
                    raise McapError(f"a metadata index points to byte {mi.offset} of {self._size}")
                rec = next(self._records_at(mi.offset))
                if not isinstance(rec, Metadata):
                    raise McapError(f"a metadata index points to a {type(rec).__name__} record")
                out[rec.name] = dict(rec.metadata)
        except Exception as e:
            raise ValueError(f"{self.path}: corrupted metadata ({_error(e)})") from None
        return out

    # ------------------------------------------------------------------ properties
    def close(self) -> None:
        self._file.close()
        self._let_go()

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

    def _iter(
        self, topics: list[str], starting_at: int | None, ending_before: int | None,
        reverse: bool = False, ordered: bool = True,
    ) -> Iterator[tuple[Channel, Message]]:
        """The messages of ``topics`` in ``[starting_at, ending_before)``: in time order
        (``reverse``: latest first; at equal times in file order, as mcap's reader), or
        chunk by chunk in file order. A chunk is read when the next message may be in it;
        while its messages wait to be yielded they count against the memory budget."""
        if not topics:
            return
        lo, hi = starting_at, ending_before
        if lo is not None and hi is not None and lo >= hi:
            return
        ids = {self._topic_ids[t] for t in topics}
        chunks = [
            ci for ci in self._summary.chunk_indexes
            if (lo is None or ci.message_end_time >= lo) and (hi is None or ci.message_start_time < hi)
            and (not ci.message_index_offsets or not ids.isdisjoint(ci.message_index_offsets))
        ]
        channels = self._summary.channels
        budget = limits.budget()
        held: dict[int, list[int]] = {}  # chunk offset -> [messages still queued, bytes held]
        try:
            if not ordered:
                for ci in sorted(chunks, key=_by_offset):
                    messages, n = self._read_chunk(ci, ids, lo, hi)
                    held[ci.chunk_start_offset] = [0, n]
                    for m in messages:
                        yield channels[m.channel_id], m
                    del held[ci.chunk_start_offset]
                    budget.release(n)
                return
            heap: list[tuple[int, int, int, Any]] = [
                (-ci.message_end_time, -(ci.chunk_start_offset + ci.chunk_length), 1, ci) if reverse
                else (ci.message_start_time, ci.chunk_start_offset, -1, ci)
                for ci in chunks
            ]
            heapq.heapify(heap)
            sign = -1 if reverse else 1
            while heap:
                _, off, _, item = heapq.heappop(heap)
                if type(item) is ChunkIndex:
                    messages, n = self._read_chunk(item, ids, lo, hi)
                    if not messages:
                        budget.release(n)
                        continue
                    at = item.chunk_start_offset
                    held[at] = [len(messages), n]
                    for i, m in enumerate(messages):
                        heapq.heappush(heap, (sign * m.log_time, sign * at, sign * i, m))
                    continue
                at = sign * off
                h = held[at]
                h[0] -= 1
                if h[0] == 0:
                    del held[at]
                    budget.release(h[1])
                yield channels[item.channel_id], item
        finally:
            for _, n in held.values():
                budget.release(n)

    def _read_chunk(self, ci: ChunkIndex, ids: set[int], lo: int | None,
                    hi: int | None) -> tuple[list[Message], int]:
        """The messages of channels ``ids`` in ``[lo, hi)`` of one chunk, in file order, and
        the bytes of the memory budget they hold (the caller releases them).

        The chunk record is read whole (its length from the index, within the limits) and
        must be the chunk its index describes; its data is decompressed no further than the
        size it declares (a chunk that decompresses to another size is refused); the CRC is
        checked; each record must lie within the chunk; a message larger than the message
        limit is refused before it is decoded."""
        where = f"{self.path}: the chunk at byte {ci.chunk_start_offset}"
        if self._file.closed:  # its descriptor may be another file's by now
            raise ValueError(f"{self.path}: the reader is closed")
        budget = limits.budget()
        need = ci.chunk_length + ci.uncompressed_size
        budget.reserve(need, f"{where}")
        try:
            try:
                data = _chunk_data(os.pread(self._fd, ci.chunk_length, ci.chunk_start_offset), ci)
            except ValueError as e:
                raise ValueError(f"{where}: corrupted data: {e}") from None
            messages, kept = self._messages_in(data, ids, lo, hi, where)
            if kept > need:  # many small messages: their objects outweigh the chunk's bytes
                budget.reserve(kept - need, f"{where}: its {len(messages)} messages")
        except BaseException:
            budget.release(need)
            raise
        if kept < need:
            budget.release(need - kept)
        return messages, kept

    def _messages_in(self, data: bytes, ids: set[int], lo: int | None, hi: int | None,
                     where: str) -> tuple[list[Message], int]:
        """The messages in a chunk's records (channels ``ids``, times ``[lo, hi)``) and the
        bytes they hold."""
        out: list[Message] = []
        kept = 0
        cap = limits.limits().max_message
        pos, n = 0, len(data)
        while pos < n:
            if pos + _RECORD_HEAD.size > n:
                raise ValueError(f"{where}: corrupted data: a record header is cut at the chunk's end")
            opcode, length = _RECORD_HEAD.unpack_from(data, pos)
            pos += _RECORD_HEAD.size
            end = pos + length
            if end > n:
                raise ValueError(f"{where}: corrupted data: a record of {length} bytes runs past the chunk's end")
            if opcode == Opcode.MESSAGE:
                if length < _MESSAGE_FIELDS.size:
                    raise ValueError(f"{where}: corrupted data: a message record of {length} bytes")
                cid, seq, log_time, publish_time = _MESSAGE_FIELDS.unpack_from(data, pos)
                if cid in ids and (lo is None or log_time >= lo) and (hi is None or log_time < hi):
                    size = length - _MESSAGE_FIELDS.size
                    if size > cap:
                        topic = self._summary.channels[cid].topic
                        raise ValueError(
                            f"{self.path}: channel {codec.short(topic)}, message at {log_time} ns: {size} bytes, "
                            f"over the limit of {cap} (review.max_message)")
                    out.append(Message(channel_id=cid, sequence=seq, log_time=log_time,
                                       publish_time=publish_time, data=data[pos + _MESSAGE_FIELDS.size:end]))
                    kept += size + MESSAGE_COST
            pos = end
        return out, kept

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

    def _chunks_by_start(self) -> tuple[list[ChunkIndex], list[int]]:
        if getattr(self, "_by_start", None) is None:
            chunks = sorted(self._summary.chunk_indexes, key=lambda c: c.message_start_time)
            self._by_start = (chunks, [c.message_start_time for c in chunks])
        return self._by_start

    def _present_before(self, topics: list[str], ns: int) -> list[str]:
        """Topics with a chunk that starts at or before ``ns`` (they may have a message then)."""
        first = self._first_chunk_ns()
        return [t for t in topics if first.get(t, ns + 1) <= ns]

    def _first_chunk_ns(self) -> dict[str, int]:
        """For each topic, the start time of the earliest chunk holding it (from the index)."""
        if getattr(self, "_first_ns", None) is None:
            names = {cid: ch.topic for cid, ch in self._summary.channels.items()}
            first: dict[str, int] = {}
            for ci in self._summary.chunk_indexes:
                if not ci.message_index_offsets:  # unindexed chunk: any topic may be in it
                    for topic in names.values():
                        first[topic] = min(first.get(topic, 1 << 63), ci.message_start_time)
                    continue
                for cid in ci.message_index_offsets:
                    topic = names.get(cid)
                    if topic is not None and ci.message_start_time < first.get(topic, 1 << 63):
                        first[topic] = ci.message_start_time
            self._first_ns: dict[str, int] | None = first
        assert self._first_ns is not None
        return self._first_ns


# ---------------------------------------------------------------------- whole sessions
def part_paths(session_id: str, directory: str | Path | None = None) -> dict[int, Path]:
    """The part files of ``session_id`` in ``directory``, by part number (empty when none):
    the regular files named ``<session_id>_<part>.mcap`` (a symbolic link is never a part).

    Two files naming the same part (``_001`` and ``_0001``) raise ValueError naming both.
    """
    root = files.sessions_dir(directory)
    found: dict[int, Path] = {}
    if not root.is_dir():
        return found
    for path in sorted(root.iterdir()):
        parsed = files.parse_part_name(path)
        if parsed is None or parsed[0] != session_id or path.is_symlink() or not path.is_file():
            continue
        if parsed[1] in found:
            raise ValueError(f"{path}: part {parsed[1]} of session {session_id!r} is also "
                             f"{found[parsed[1]].name}; keep one of the two")
        found[parsed[1]] = path
    return found


def _sequence(session_id: str, folder: Path) -> list[Path]:
    """The part files of a session in part order; ValueError naming the first missing one."""
    found = part_paths(session_id, folder)
    if not found:
        raise ValueError(f"session {session_id!r}: no files in {folder}")
    for n in range(1, max(found) + 1):
        if n not in found:
            have = ", ".join(p.name for _, p in sorted(found.items()))
            raise ValueError(f"{folder / files.part_name(session_id, n)}: no such file: part {n} "
                             f"of session {session_id!r} is missing (found {have})")
    return [found[n] for n in sorted(found)]


def _named_file(session: str | Path, root: Path) -> Path | None:
    """The file ``session`` names (as given, else inside ``root``), None when it names none.

    A ``Path``, or text holding a path separator or ending in ``.mcap``, names a file
    (ValueError when there is none); any other text is a session id (None).
    """
    text = str(session)
    is_path = isinstance(session, Path) or "/" in text or "\\" in text
    if not is_path and not text.endswith(files.SUFFIX):
        return None
    p = Path(text).expanduser()
    for candidate in (p,) if p.is_absolute() else (p, root / p):
        if candidate.is_file():
            return candidate
    raise ValueError(f"{session}: no such session file")


def _paths_of(session: str | Path, root: Path, confined: bool = True) -> tuple[str | None, list[Path]]:
    """(session id, part files in order) named by a session id or by one of its parts;
    the id is None for a file whose name is not a part name (it is read alone). A named
    file outside ``root`` is refused when ``confined`` (:func:`files.session_path`)."""
    given = _named_file(session, root)
    if given is None:
        sid = str(session)
        if not sid:
            raise ValueError("session: no session id given")
        return sid, _sequence(sid, root)
    p = files.session_path(given, root, confined=confined)
    parsed = files.parse_part_name(p)
    if parsed is None:
        return None, [p]
    return parsed[0], _sequence(parsed[0], p.parent)


def session_files(session: str | Path, directory: str | Path | None = None) -> list[Path]:
    """The part files :class:`SessionParts` opens for ``session``, in part order."""
    return _paths_of(session, files.sessions_dir(directory))[1]


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
                 confined: bool = True) -> None:
        root = files.sessions_dir(directory)
        sid, paths = _paths_of(session, root, confined)
        readers: list[SessionReader] = []
        try:
            for path in paths:  # a truncated part: TruncatedSessionError naming it
                readers.append(SessionReader(path, root, confined=confined))
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
                 confined: bool = True) -> SessionParts:
    """Open a whole session inside ``directory`` (default: the project's ``sessions/``).

    ``session``: a session id, or the path or file name of any one of its parts (every
    part is opened); a file whose name is not a part name is opened alone. A one-part
    session reads exactly as its file does with :class:`SessionReader`. ``confined=False``:
    a named file is read wherever it is (a path the user typed, :func:`files.session_path`).
    """
    return SessionParts(session, directory, confined=confined)
