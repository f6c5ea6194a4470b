"""The recorder's MCAP writer writes the same bytes as mcap's own ``Writer`` and knows where
the file last ended on a complete chunk."""

from __future__ import annotations

import io
import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.exceptions import EndOfFile
from mcap.stream_reader import StreamReader
from mcap.records import Chunk, MessageIndex
from mcap.writer import CompressionType, Writer

from ucat_console.backend.sessions.mcap_writer import ChunkedWriter

_U64 = 2**64 - 1


def _session(writer_class, steps, *, chunk_size: int, compression: CompressionType) -> bytes:
    out = io.BytesIO()
    w = writer_class(out, chunk_size=chunk_size, compression=compression)
    w.start(profile="ucat", library="test")
    w.add_metadata("session", {"id": "x"})
    schema = w.register_schema("s", "jsonschema", b"{}")
    channels = [w.register_channel(f"topic/{i}", "json", schema) for i in range(5)]
    for step in steps:
        if step[0] == "flush":
            w.flush()
        elif step[0] == "metadata":
            w.add_metadata("notes", {"text": step[1]})
        else:
            _, ch, log_time, data, publish_time, sequence = step
            w.add_message(channels[ch], log_time=log_time, data=data, publish_time=publish_time, sequence=sequence)
    w.finish()
    return out.getvalue()


_message = st.tuples(st.just("message"), st.integers(0, 4), st.integers(0, _U64), st.binary(max_size=300),
                     st.integers(0, _U64), st.integers(0, 2**32 - 1))
_steps = st.lists(st.one_of(_message, _message, _message, _message, st.tuples(st.just("flush")),
                            st.tuples(st.just("metadata"), st.text(max_size=20))), max_size=120)


@settings(max_examples=150, deadline=None)
@given(steps=_steps, chunk_size=st.sampled_from([64, 1024, 64 * 1024]),
       compression=st.sampled_from([CompressionType.ZSTD, CompressionType.LZ4, CompressionType.NONE]))
def test_the_same_bytes_as_mcaps_writer(steps, chunk_size, compression):
    """Any sequence of messages (times in any order, empty and long data, every channel),
    flushes and metadata, with chunks closed by size or by a flush: the same file."""
    ours = _session(ChunkedWriter, steps, chunk_size=chunk_size, compression=compression)
    theirs = _session(Writer, steps, chunk_size=chunk_size, compression=compression)
    assert ours == theirs


def test_a_recorder_sized_session_reads_back_with_its_index():
    """A few thousand messages over many chunks: the same bytes, and mcap's reader finds
    every message through the file's index, in log-time order."""
    rng = random.Random(7)
    steps, t = [], 1_700_000_000_000_000_000
    for i in range(5000):
        t += rng.randrange(0, 3_000_000)
        steps.append(("message", rng.randrange(5), t - rng.randrange(0, 20_000_000), rng.randbytes(rng.randrange(40, 400)),
                      t, i))
        if i % 777 == 0:
            steps.append(("flush",))
    data = _session(ChunkedWriter, steps, chunk_size=16 * 1024, compression=CompressionType.ZSTD)
    assert data == _session(Writer, steps, chunk_size=16 * 1024, compression=CompressionType.ZSTD)
    reader = make_reader(io.BytesIO(data))
    summary = reader.get_summary()
    assert summary is not None and summary.statistics.message_count == 5000
    assert len(summary.chunk_indexes) > 10
    times = [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)]
    assert times == sorted(s[2] for s in steps if s[0] == "message")


@pytest.mark.parametrize("bad", [-1, 2**64])
def test_a_time_out_of_range_is_refused_as_mcaps_writer_refuses_it(bad):
    """A log time that does not fit the record's field fails, as it does in mcap's writer,
    rather than being written wrapped."""
    for writer_class in (Writer, ChunkedWriter):
        w = writer_class(io.BytesIO(), chunk_size=1024, compression=CompressionType.NONE)
        w.start(profile="", library="")
        ch = w.register_channel("t", "json", w.register_schema("s", "jsonschema", b"{}"))
        with pytest.raises(Exception):
            w.add_message(ch, log_time=bad, data=b"{}", publish_time=0, sequence=0)


def test_complete_is_the_end_of_the_last_chunk_and_its_indexes():
    """After every message, ``complete`` is where the output last ended on a whole chunk
    followed by its message indexes (all of it handed over to the file), and ``complete_ns``
    the latest message time written up to there: a file cut back to ``complete`` holds
    exactly the messages up to ``complete_ns``, each in a chunk read whole."""
    out = io.BytesIO()
    w = ChunkedWriter(out, chunk_size=2048, compression=CompressionType.ZSTD)
    w.start(profile="ucat", library="test")
    ch = w.register_channel("t", "json", w.register_schema("s", "jsonschema", b"{}"))
    rng = random.Random(3)
    seen, moves = [], 0
    for i in range(600):
        before = w.complete
        ns = 1_000 + i * 10 + rng.randrange(5)
        w.add_message(ch, log_time=ns, data=rng.randbytes(rng.randrange(10, 200)), publish_time=ns, sequence=i)
        seen.append(ns)
        if w.complete != before:
            moves += 1
            assert w.complete == out.tell()  # nothing of an open chunk written after it
            assert w.complete_ns == max(seen)
            records = _records_until_cut(out.getvalue()[: w.complete])
            assert isinstance(records[-1], MessageIndex)
            chunks = [r for r in records if isinstance(r, Chunk)]
            assert chunks and chunks[-1].message_end_time == w.complete_ns
    assert moves > 10
    w.flush()
    assert w.complete == out.tell() and w.complete_ns == max(seen)


def _records_until_cut(data: bytes) -> list:
    """The whole records of a file cut off after a record (mcap's reader ends at the cut)."""
    records = []
    try:
        for r in StreamReader(io.BytesIO(data), skip_magic=False, emit_chunks=True).records:
            records.append(r)
    except EndOfFile:
        pass
    return records
