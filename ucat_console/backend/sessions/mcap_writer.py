"""mcap's ``Writer`` with its per-message path written out: the same file, byte for byte.

The recorder writes about 700 records a second at the pool side (440 telemetry messages
and the transforms derived from them). mcap's ``Writer.add_message`` builds a ``Message``
record object for each, and its chunk builder writes it field by field (seven calls, each
packing one integer into a ``BytesIO``), then writes each chunk's message index one
integer at a time: about 7 us a message in a tight loop on the development machine, most
of the recorder thread's CPU. :class:`ChunkedWriter` is that ``Writer`` with two things
replaced:

* :meth:`ChunkedWriter.add_message` updates the file's statistics as mcap's does and
  appends the record to the open chunk with one ``struct`` pack of its header fields;
* each chunk's message index is kept as a flat list of (time, offset) and written with one
  pack (:class:`_MessageIndex`).

Everything else (the header, schemas, channels, metadata, closing and compressing
chunks, the summary, the footer, the CRCs) is mcap's own code. The two replaced parts
use the ``Writer``'s private attributes (``_Writer__statistics``, ``_Writer__chunk_builder``,
``_Writer__finalize_chunk``); checked against mcap 1.6.0, the version ``constraints.txt``
pins. ``tests/backend/sessions/test_mcap_writer.py`` writes the same random sessions
with both writers and checks that the files are the same bytes.
"""

from __future__ import annotations

import struct
from typing import IO, Any

from mcap._chunk_builder import ChunkBuilder
from mcap.records import MessageIndex
from mcap.opcode import Opcode
from mcap.writer import CompressionType, Writer

_MESSAGE_HEADER = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
_MESSAGE_FIELDS = 2 + 4 + 8 + 8  # the record's fields before its data
_INDEX_HEADER = struct.Struct("<BQHI")  # opcode, record length, channel, records' length
_OPCODE_MESSAGE = int(Opcode.MESSAGE)
_OPCODE_MESSAGE_INDEX = int(Opcode.MESSAGE_INDEX)


class _MessageIndex(MessageIndex):
    """A chunk's index of one channel, its (log time, offset) pairs as one flat list."""

    def __init__(self, channel_id: int) -> None:
        super().__init__(channel_id=channel_id, records=[])

    def write(self, stream: Any) -> None:
        flat = self.records
        n = len(flat)  # two numbers a message: 8 bytes each
        stream.write(_INDEX_HEADER.pack(_OPCODE_MESSAGE_INDEX, 2 + 4 + 8 * n, self.channel_id, 8 * n))
        stream.write(struct.pack(f"<{n}Q", *flat))


class _ChunkBuilder(ChunkBuilder):
    """mcap's chunk builder with a one-pack message append (:meth:`append`)."""

    def append(self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int) -> None:
        if self.num_messages == 0:
            self.message_start_time = log_time
        elif log_time < self.message_start_time:
            self.message_start_time = log_time
        if log_time > self.message_end_time:
            self.message_end_time = log_time
        index = self.message_indices.get(channel_id)
        if index is None:
            index = self.message_indices[channel_id] = _MessageIndex(channel_id)
        buf = self.record_writer._buffer
        index.records += (log_time, buf.tell())
        self.num_messages += 1
        buf.write(_MESSAGE_HEADER.pack(_OPCODE_MESSAGE, _MESSAGE_FIELDS + len(data), channel_id, sequence,
                                       log_time, publish_time))
        buf.write(data)


class ChunkedWriter(Writer):
    """``mcap.writer.Writer`` (always chunked) with the per-message path of the module
    docstring; the rest of its interface is mcap's."""

    def __init__(self, output: IO[bytes], *, chunk_size: int, compression: CompressionType) -> None:
        super().__init__(output, chunk_size=chunk_size, compression=compression, use_chunking=True)
        self._chunk = _ChunkBuilder()
        self._Writer__chunk_builder = self._chunk
        self._stats = self._Writer__statistics
        self._counts = self._stats.channel_message_counts
        self._limit = chunk_size
        self._output = output
        #: the output's length when it last ended on a complete chunk, handed to the OS, and
        #: the latest message time in it (what survives a failed write after it)
        self.complete = 0
        self.complete_ns = 0

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
                    sequence: int = 0) -> None:
        stats = self._stats
        if stats.message_count == 0:
            stats.message_start_time = log_time
        elif log_time < stats.message_start_time:
            stats.message_start_time = log_time
        if log_time > stats.message_end_time:
            stats.message_end_time = log_time
        self._counts[channel_id] += 1
        stats.message_count += 1
        chunk = self._chunk
        chunk.append(channel_id, log_time, data, publish_time, sequence)
        if chunk.record_writer._buffer.tell() > self._limit:
            self._Writer__finalize_chunk()
            self.handed_over()

    def flush(self) -> None:
        super().flush()
        self.handed_over()

    def handed_over(self) -> None:
        """The output ends on a complete record: hand it to the OS and note where."""
        self._output.flush()
        self.complete = self._output.tell()
        self.complete_ns = self._stats.message_end_time
