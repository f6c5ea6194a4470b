"""Reading MCAP files within the limits, beside :mod:`.mcap_writer`: the summary, the metadata
and the chunks of one file, as mcap's records and messages (not decoded).

:class:`McapFile` is the low-level half of :class:`~.reader.SessionReader` (which decodes
the messages into the telemetry dataclasses and checks the channels are ours). Within the
limits of :mod:`~ucat_console.backend.sessions.limits`: the summary, the metadata and each
chunk are read with mcap's record reader (``StreamReader``, chunks emitted whole: nothing
is decompressed behind the limits' back), each chunk checked against its index and
decompressed here no further than it declares. Reads use ``os.pread``: one file may serve
several threads. A file with no readable summary raises :class:`TruncatedSessionError`
(``repair`` recovers it).
"""

from __future__ import annotations

import heapq
import io
import os
import struct
import zlib
from pathlib import Path
from typing import IO, Any, Iterator

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

from ucat_console.backend.sessions import codec, limits

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


def record_limit(cfg: limits.ReviewConfig) -> int:
    """The largest record read whole: a chunk within ``cfg``'s limit, compressed (zstd and
    lz4 add a little to data that does not compress), with its header."""
    cap = cfg.max_chunk
    return cap + cap // 64 + 4096


def _error(e: BaseException) -> str:
    text = str(e)
    return f"{type(e).__name__}: {text if len(text) <= 200 else text[:197] + '...'}"


def _by_offset(ci: ChunkIndex) -> int:
    return ci.chunk_start_offset


def _chunk_data(body: bytes, ci: ChunkIndex, cfg: limits.ReviewConfig) -> bytes:
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
    return decompressed(chunk, cfg)


def decompressed(chunk: Chunk, cfg: limits.ReviewConfig) -> bytes:
    """A chunk's records, decompressed within ``cfg``'s chunk limit, CRC checked (ValueError)."""
    cap = cfg.max_chunk
    if chunk.uncompressed_size > cap:
        raise ValueError(f"it decompresses to {chunk.uncompressed_size} bytes, over the limit of "
                         f"{cap} (review.max_chunk)")
    data = limits.decompress(chunk.compression, chunk.data, chunk.uncompressed_size)
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ValueError("its CRC does not match its data")
    return data


class TruncatedSessionError(ValueError):
    """The file has no readable summary (a killed recorder): ``repair`` recovers it."""


class BudgetHolder:
    """Holds bytes of its ``budget`` while open (summary, metadata, event index) and lets
    them go on closing; the opener sets ``budget``."""

    path: Path
    budget: limits.MemoryBudget
    _held = 0  # bytes of the memory budget held while open

    def _hold(self, n: int, what: str) -> None:
        self.budget.reserve(n, f"{self.path}: {what}")
        self._held += n

    def _let_go(self) -> None:
        held, self._held = self._held, 0
        self.budget.release(held)


class McapFile(BudgetHolder):
    """One MCAP file's summary, metadata and chunks (module docstring); the opener sets
    ``path``, ``_file``, ``_fd``, ``_size``, ``_summary`` and ``_topic_ids`` (topic ->
    channel id)."""

    _file: IO[bytes]
    _fd: int
    _size: int
    _summary: Summary
    _topic_ids: dict[str, int]

    def _records_at(self, offset: int) -> Iterator[Any]:
        """mcap's record reader from ``offset`` (chunks emitted whole, records within the
        limits' largest record)."""
        self._file.seek(offset)
        return StreamReader(self._file, skip_magic=True, emit_chunks=True,
                            record_size_limit=record_limit(self.budget.config)).records

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
        p, cap, stats = self.path, self.budget.config.max_chunk, summary.statistics
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
                    and ci.chunk_length <= record_limit(self.budget.config)):
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

    def close(self) -> None:
        self._file.close()
        self._let_go()

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
        budget = self.budget
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
        budget = self.budget
        need = ci.chunk_length + ci.uncompressed_size
        budget.reserve(need, f"{where}")
        try:
            try:
                data = _chunk_data(os.pread(self._fd, ci.chunk_length, ci.chunk_start_offset), ci, self.budget.config)
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
        cap = self.budget.config.max_message
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
