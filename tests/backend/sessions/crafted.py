"""Crafted session files: a real recording's schemas, channels and metadata around chunks
the test makes (padded, lying about their sizes, overlapping), written record by record
with mcap's record classes, so that nothing in the writer checks what they say."""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import lz4.frame
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
)

MAGIC = b"\x89MCAP0\r\n"
_MESSAGE = struct.Struct("<BQHIQQ")


def message_record(channel_id: int, log_time: int, data: bytes, sequence: int = 0) -> bytes:
    return _MESSAGE.pack(Opcode.MESSAGE, 22 + len(data), channel_id, sequence, log_time, log_time) + data


@dataclass
class CraftedChunk:
    """A chunk as it is written: compressed ``data`` and what its header and index say."""

    data: bytes
    uncompressed_size: int
    crc: int
    compression: str
    start: int
    end: int
    index_uncompressed_size: int | None = None  # what the index says (None: the header's)
    index_compressed_size: int | None = None
    index_channels: tuple[int, ...] = ()  # the channels the index lists (none: any may be in it)


def chunk_of(records: Iterable[bytes], start: int, end: int, compression: str = "zstd",
             content_size: bool = True) -> CraftedChunk:
    """A chunk of ``records`` (each an encoded record; an iterable may stream a large one in
    pieces). zstd with ``content_size`` False writes a frame without its size (streamed)."""
    size, crc = 0, 0
    if compression == "zstd" and not content_size:
        cobj = zstandard.ZstdCompressor().compressobj()
        out = []
        for piece in records:
            size += len(piece)
            crc = zlib.crc32(piece, crc)
            out.append(cobj.compress(piece))
        out.append(cobj.flush())
        return CraftedChunk(b"".join(out), size, crc, "zstd", start, end)
    raw = b"".join(records)
    data = {"zstd": lambda: zstandard.ZstdCompressor().compress(raw),
            "lz4": lambda: lz4.frame.compress(raw), "": lambda: raw}[compression]()
    return CraftedChunk(data, len(raw), zlib.crc32(raw), compression, start, end)


@dataclass
class Base:
    """What a crafted file takes from a real recording."""

    schemas: list[Schema]
    channels: list[Channel]
    metadata: list[Metadata]
    topic_ids: dict[str, int] = field(default_factory=dict)

    @classmethod
    def of(cls, path: Path) -> Base:
        with open(path, "rb") as fh:
            r = make_reader(fh)
            s = r.get_summary()
            assert s is not None
            metadata = list(r.iter_metadata())
        chans = list(s.channels.values())
        return cls(list(s.schemas.values()), chans, metadata, {c.topic: c.id for c in chans})


def _record(rec: object) -> bytes:
    b = RecordBuilder()
    rec.write(b)  # type: ignore[attr-defined]
    return b.end()


def write(path: Path, base: Base, chunks: list[CraftedChunk], *, summary_start: int | None = None) -> Path:
    """The file: header, metadata, the chunks, then a summary indexing them (its footer's
    summary start replaced by ``summary_start`` when given)."""
    out = bytearray(MAGIC)
    out += _record(Header(profile="ucat_console", library="crafted"))
    meta_index = []
    for m in base.metadata:
        at = len(out)
        out += _record(m)
        meta_index.append(MetadataIndex(offset=at, length=len(out) - at, name=m.name))
    indexes = []
    for c in chunks:
        at = len(out)
        out += _record(Chunk(message_start_time=c.start, message_end_time=c.end,
                             uncompressed_size=c.uncompressed_size, uncompressed_crc=c.crc,
                             compression=c.compression, data=c.data))
        indexes.append(ChunkIndex(
            message_start_time=c.start, message_end_time=c.end, chunk_start_offset=at,
            chunk_length=len(out) - at, message_index_offsets={cid: 0 for cid in c.index_channels},
            message_index_length=0,
            compression=c.compression,
            compressed_size=len(c.data) if c.index_compressed_size is None else c.index_compressed_size,
            uncompressed_size=c.uncompressed_size if c.index_uncompressed_size is None
            else c.index_uncompressed_size))
    out += _record(DataEnd(data_section_crc=0))
    start = len(out)
    for s in base.schemas:
        out += _record(s)
    for ch in base.channels:
        out += _record(ch)
    out += _record(Statistics(
        message_count=len(chunks), schema_count=len(base.schemas), channel_count=len(base.channels),
        attachment_count=0, metadata_count=len(base.metadata), chunk_count=len(chunks),
        message_start_time=min((c.start for c in chunks), default=0),
        message_end_time=max((c.end for c in chunks), default=0),
        channel_message_counts={ch.id: 1 for ch in base.channels}))
    for ci in indexes:
        out += _record(ci)
    for mi in meta_index:
        out += _record(mi)
    out += _record(Footer(summary_start=start if summary_start is None else summary_start,
                          summary_offset_start=0, summary_crc=0))
    out += MAGIC
    path.write_bytes(bytes(out))
    return path
