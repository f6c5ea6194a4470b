"""Repair a truncated session file (a killed recorder leaves no footer or summary).

Every complete record (schemas, channels, messages, metadata, attachments) is read
sequentially with mcap's ``StreamReader`` (the record reader under ``NonSeekingReader``,
which stops with an error at the cut), chunks emitted whole and opened here within the
limits of :mod:`.limits` (CRCs checked, so a half-written chunk is left out; a chunk or a
message over its limit, or a chunk that decompresses to another size than it declares,
ends the copy like a damaged record), and copied into a new ``Writer``, which writes the chunk,
message and metadata indexes and the summary: the result opens like any finished file.
The copy goes to a temporary file beside the original and then atomically replaces it,
so the session opens under its name again; the original is kept, unchanged, as
``<name>.orig.mcap`` beside it (:func:`files.original_name`), where the listing shows it
(unless told otherwise: ``sessions repair --no-keep``). A kept original is never rewritten.

A file a recorder is writing (the part being recorded now, in this process or another:
:mod:`.writing`) is refused: its end is still being written, and replacing it would cut
the recording short.
"""

from __future__ import annotations

import logging
import os
import shutil
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Iterator

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader
from mcap.records import Attachment, Channel, Chunk, DataEnd, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

from ucat_console.backend.sessions import files, limits, writing
from ucat_console.backend.sessions.mcap_read import MAGIC, TruncatedSessionError, decompressed, record_limit
from ucat_console.backend.sessions.reader import SessionReader

log = logging.getLogger(__name__)

_CHUNK_SIZE = 256 * 1024


@dataclass(frozen=True)
class RepairReport:
    path: Path
    repaired: bool  # False: the file was already complete, nothing was written
    messages: int  # messages in the repaired file
    metadata: int  # metadata records copied
    stop_reason: str  # why reading stopped ("" for a complete file)
    original: Path | None  # where the original was kept


def needs_repair(path: str | Path, budget: limits.MemoryBudget | None = None) -> bool:
    """True when the file has no readable summary (it opens only after a repair)."""
    p = Path(path)
    try:
        SessionReader(p, p.resolve().parent, budget=budget).close()
    except TruncatedSessionError:
        return True
    except ValueError:
        return False
    return False


def repair(
    path: str | Path,
    directory: str | Path | None = None,
    *,
    keep_original: bool = True,
    force: bool = False,
    confined: bool = True,
    budget: limits.MemoryBudget | None = None,
) -> RepairReport:
    """Rewrite ``path`` fully indexed from its complete records.

    A file that already opens is left alone (``repaired`` False) unless ``force``; a file
    being recorded, and an original a repair kept, are refused (ValueError). ``confined``:
    ``path`` must lie in the sessions directory (:func:`files.session_path`). The file is
    read within ``budget``'s limits (default: one of its own).
    """
    budget = budget if budget is not None else limits.MemoryBudget()
    cfg = budget.config
    p = files.session_path(path, directory, confined=confined)
    if not p.is_file():
        raise ValueError(f"{path}: no such session file")
    if files.original_of(p.name):
        raise ValueError(f"repair: {p.name} is the original a repair of {files.original_of(p.name)} kept; "
                         "a repair never rewrites it")
    if writing.being_written(p):
        raise ValueError(f"repair: {p.name} is being recorded; stop the recording first")
    with open(p, "rb") as fh:
        if fh.read(len(MAGIC)) != MAGIC:
            raise ValueError(f"{p}: not an MCAP file (it does not start with the MCAP magic)")
    if not force and not needs_repair(p, budget):
        with SessionReader(p, p.parent, budget=budget) as r:
            return RepairReport(p, False, r.message_count, len(r.metadata), "", None)

    with open(p, "rb") as fh:
        try:
            header = NonSeekingReader(fh, record_size_limit=record_limit(cfg)).get_header()
        except Exception as e:
            raise ValueError(f"{p}: not repairable: no complete MCAP header ({e})") from None

    tmp = p.with_name(p.name + ".repair-tmp")
    counts = {"messages": 0, "metadata": 0}
    stop = ""
    try:
        with open(p, "rb") as src, open(tmp, "wb") as out:
            w = Writer(out, chunk_size=_CHUNK_SIZE, compression=CompressionType.ZSTD)
            w.start(profile=header.profile, library=header.library)
            records = StreamReader(src, validate_crcs=True, emit_chunks=True, record_size_limit=record_limit(cfg))
            stop = _copy_records(_unchunked(records.records, cfg), w, counts)
            w.finish()
            out.flush()
            os.fsync(out.fileno())
        original = _keep(p) if keep_original else None
        os.replace(tmp, p)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    n = counts["messages"]
    log.info("repaired %s: %d messages recovered (%s)", p, n, stop or "complete")
    return RepairReport(p, True, n, counts["metadata"], stop, original)


def _unchunked(records: Iterator[Any], cfg: limits.ReviewConfig) -> Iterator[Any]:
    """The records, those of each chunk in its place (opened within ``cfg``'s limits)."""
    cap = cfg.max_message
    for rec in records:
        if not isinstance(rec, Chunk):
            yield rec
            continue
        try:
            inner = breakup_chunk(replace(rec, compression="", data=decompressed(rec, cfg), uncompressed_crc=0))
        except ValueError as e:
            raise McapError(f"a chunk: {e}") from None
        for r in inner:
            if isinstance(r, Message) and len(r.data) > cap:
                raise McapError(f"a message of {len(r.data)} bytes, over the limit of {cap} (review.max_message)")
            yield r


def _copy_records(records: Iterator[Any], w: Writer, counts: dict[str, int]) -> str:
    """Copy schemas, channels, messages, metadata and attachments until the records end
    (a finished file) or break off (the cut); returns why reading stopped."""
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    try:
        for rec in records:
            if isinstance(rec, Schema):
                if rec.id not in schema_ids:
                    schema_ids[rec.id] = w.register_schema(rec.name, rec.encoding, rec.data)
            elif isinstance(rec, Channel):
                if rec.id not in channel_ids:
                    if rec.schema_id and rec.schema_id not in schema_ids:
                        raise McapError(f"channel {rec.topic!r}: no schema record {rec.schema_id}")
                    channel_ids[rec.id] = w.register_channel(
                        rec.topic, rec.message_encoding, schema_ids.get(rec.schema_id, 0),
                        dict(rec.metadata),
                    )
            elif isinstance(rec, Message):
                if rec.channel_id not in channel_ids:
                    raise McapError(f"message on unknown channel {rec.channel_id}")
                w.add_message(
                    channel_ids[rec.channel_id], log_time=rec.log_time, data=rec.data,
                    publish_time=rec.publish_time, sequence=rec.sequence,
                )
                counts["messages"] += 1
            elif isinstance(rec, Metadata):
                w.add_metadata(rec.name, dict(rec.metadata))
                counts["metadata"] += 1
            elif isinstance(rec, Attachment):
                w.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
            elif isinstance(rec, DataEnd):
                return ""
    except Exception as e:  # the cut, or a damaged record
        return f"{type(e).__name__}: {e}"
    return ""


def _keep(p: Path) -> Path:
    """Keep the original as ``<name>.orig.mcap`` (an earlier one, from a first repair, is kept)."""
    original = p.with_name(files.original_name(p.name))
    if not original.exists():
        try:
            os.link(p, original)
        except OSError:
            shutil.copy2(p, original)
    return original
