"""What reading a session file may cost: a session file is untrusted input.

A session file a few megabytes long can hold chunks that decompress to gigabytes, a message
padded to hundreds of megabytes, JSON nested a hundred thousand deep, a summary that
describes millions of chunks, or sizes in its headers that lie. Everything that reads one
(review, playback, export, replay, listing, repair) goes through the limits here:

* ``max_message``: the largest message (bytes of JSON); a larger one is refused, naming the
  file, the channel and the time, before it is decoded;
* ``max_chunk``: the largest chunk, decompressed (and the largest record read from the file
  whole). A chunk's declared size is checked before anything is decompressed, and the
  decompression itself stops at the declared size (a chunk whose data decompresses to more
  or less than it declares is refused as corrupted, whatever its headers say);
* ``memory``: what the readings sharing one :class:`MemoryBudget` may hold at once (the
  console's budget, owned by its supervisor, is every page's and every review's; a command
  of the shell reads within a budget of its own): each open file's summary and event index,
  and each chunk a reading holds decompressed. A reading that would go over is refused with
  the amounts; what it held is given back.

:data:`MAX_JSON_DEPTH` bounds the nesting of JSON in a file (messages, schemas, markers).

The recorder writes chunks of at most 256 KiB and messages of a few kilobytes, so the
defaults leave a wide margin for every file the console writes.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import lz4.frame
import zstandard

from ucat_console.typedconf import Config, param

#: the deepest JSON nesting read from a session file (our messages nest three deep)
MAX_JSON_DEPTH = 64
_MIB = 1024 * 1024


@dataclass(frozen=True)
class ReviewConfig(Config):
    """Limits on reading session files (review, playback, export, replay): files are untrusted input."""

    max_message: int = param(
        1 * _MIB, lo=4096, hi=1024 * _MIB, unit="B",
        doc="the largest message read from a session file (bytes of JSON); a larger one is refused",
    )
    max_chunk: int = param(
        8 * _MIB, lo=64 * 1024, hi=4096 * _MIB, unit="B",
        doc="the largest chunk of a session file, decompressed; a larger one is refused",
    )
    memory: int = param(
        512 * _MIB, lo=16 * _MIB, hi=1024 * 1024 * _MIB, unit="B",
        doc="what reading session files may hold at once, over every open file and page "
        "(summaries, event indexes, decompressed chunks); a reading that would go over is refused",
    )

    def _check(self) -> None:
        if self.max_message > self.max_chunk:
            raise ValueError(f"max_message: {self.max_message} B is larger than max_chunk {self.max_chunk} B; "
                             "a message is read from within a chunk")
        if 2 * self.max_chunk > self.memory:
            raise ValueError(f"memory: {self.memory} B holds fewer than two chunks of max_chunk "
                             f"{self.max_chunk} B; allowed: at least {2 * self.max_chunk} B")


def mb(n: int) -> str:
    return f"{n / _MIB:.1f} MiB"


class MemoryExceeded(ValueError):
    """A reading would hold more than the memory cap allows."""


class MemoryBudget:
    """The bytes that readings of session files hold, against ``config.memory``; thread-safe.

    ``reserve(n, what)`` before holding ``n`` bytes (MemoryExceeded naming ``what`` and the
    amounts when that would go over the cap), ``release(n)`` when they are let go."""

    def __init__(self, config: ReviewConfig | None = None) -> None:
        self.config = config or ReviewConfig()
        self._lock = threading.Lock()
        self.used = 0
        self.peak = 0

    def reserve(self, n: int, what: str) -> None:
        with self._lock:
            cap = self.config.memory
            if self.used + n > cap:
                raise MemoryExceeded(
                    f"{what}: needs {mb(n)} of memory and {mb(self.used)} of the {mb(cap)} that reading "
                    "session files may hold (review.memory) is in use; close a review or retry later")
            self.used += n
            if self.used > self.peak:
                self.peak = self.used

    def release(self, n: int) -> None:
        with self._lock:
            self.used = max(0, self.used - n)


def decompress(compression: str, data: bytes, size: int) -> bytes:
    """A chunk's ``data`` decompressed, which must come to the ``size`` bytes it declares
    (ValueError otherwise): no more than ``size`` bytes are ever produced, whatever a
    compression frame's own header says."""
    if compression == "":
        out = data
    elif compression == "zstd":
        declared = zstandard.frame_content_size(data)  # -1: not in the frame's header
        if declared not in (-1, size):
            raise ValueError(f"its zstd frame declares {declared} bytes, the chunk {size}")
        try:
            out = zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
        except zstandard.ZstdError as e:
            raise ValueError(f"zstd: {e} (the chunk declares {size} bytes)") from None
    elif compression == "lz4":
        d = lz4.frame.LZ4FrameDecompressor()
        try:
            out = d.decompress(data, max_length=size + 1)
        except RuntimeError as e:
            raise ValueError(f"lz4: {e} (the chunk declares {size} bytes)") from None
        if len(out) == size and not d.eof:
            raise ValueError(f"its lz4 frame holds more than the {size} bytes the chunk declares")
    else:
        raise ValueError(f"unknown compression {compression[:20]!r}")
    if len(out) != size:
        got = f"more than {size}" if len(out) > size else f"{len(out)}"
        raise ValueError(f"it decompresses to {got} bytes, not the {size} it declares")
    return out
