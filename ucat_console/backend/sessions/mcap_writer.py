"""The recorder's MCAP writer: mcap's public ``Writer``, telling where the file last ended
on a complete chunk.

Crash safety needs to know, after each message, whether the output now ends on a whole
record handed to the OS: a failed write cuts the part back to there
(:meth:`~ucat_console.backend.sessions.recorder._Part.abandon`) and ``repair`` indexes
everything up to it. mcap's ``Writer`` writes nothing to its output while a chunk is
open and writes a closed chunk with its message indexes within the ``add_message`` call
that filled it (or within ``flush``), so the output's position moving during such a call
is exactly a chunk (and its indexes) written: :class:`ChunkedWriter` then flushes the
output to the OS and notes its length (:attr:`ChunkedWriter.complete`) and the latest
message time in it (:attr:`ChunkedWriter.complete_ns`).

Only mcap's public interface is used (``mcap.writer.Writer`` and its methods); the
output must be a buffered binary stream whose ``tell`` counts what was written to it
(the recorder's ``open(path, "xb")``).
"""

from __future__ import annotations

from typing import IO

from mcap.writer import CompressionType, Writer


class ChunkedWriter(Writer):
    """``mcap.writer.Writer`` (always chunked) that hands each closed chunk to the OS and
    notes where it ends (module docstring); the rest of its interface is mcap's."""

    def __init__(self, output: IO[bytes], *, chunk_size: int, compression: CompressionType) -> None:
        super().__init__(output, chunk_size=chunk_size, compression=compression, use_chunking=True)
        self._output = output
        self._written = 0  # the output's position after the last call that wrote to it
        self._latest_ns = 0  # the latest message time added
        self._open_ns: int | None = None  # the earliest message time not yet handed over
        #: the output's length when it last ended on a complete chunk, handed to the OS
        self.complete = 0
        #: the latest message time handed over (messages come in publication order, which
        #: may differ from their times by a little: what is kept is :attr:`kept_ns`)
        self.complete_ns = 0

    def start(self, profile: str = "", library: str = "") -> None:
        super().start(profile=profile, library=library)
        self._written = self._output.tell()  # the header: not yet a chunk to keep

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
                    sequence: int = 0) -> None:
        if self._open_ns is None or log_time < self._open_ns:
            self._open_ns = log_time  # before the write: a failed one loses it
        super().add_message(channel_id, log_time=log_time, data=data, publish_time=publish_time, sequence=sequence)
        if log_time > self._latest_ns:
            self._latest_ns = log_time
        if self._output.tell() != self._written:  # the message closed the chunk: it is written
            self.handed_over()

    def flush(self) -> None:
        super().flush()
        self.handed_over()

    def handed_over(self) -> None:
        """The output ends on a complete record: hand it to the OS and note where."""
        self._output.flush()
        self.complete = self._written = self._output.tell()
        self.complete_ns = self._latest_ns
        self._open_ns = None

    @property
    def kept_ns(self) -> int:
        """Every message with this time or an earlier one is in the complete chunks, but for
        messages of the same time published after the last one handed over (ns)."""
        return self.complete_ns if self._open_ns is None else min(self._open_ns - 1, self.complete_ns)
