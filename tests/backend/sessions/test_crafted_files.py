"""Session files are untrusted input: crafted files are refused with a message naming the
file and what is wrong, or read within the limits (memory measured with tracemalloc and
with the limits' own accounting); the folder's symbolic links and odd entries are skipped
and listed as such; a reader is shared by everyone reviewing a session."""

from __future__ import annotations

import os
import tracemalloc
from pathlib import Path
from typing import Iterator

import pytest
from crafted import Base, CraftedChunk, chunk_of, message_record, write
from mcap.reader import make_reader
from session_helpers import example_message, record

from ucat_console.backend.sessions import codec, index, limits, shared
from ucat_console.backend.sessions.mcap_read import TruncatedSessionError
from ucat_console.backend.sessions.reader import SessionParts, SessionReader
from ucat_console.backend.sessions.recorder import RecorderConfig
from ucat_console.cli import main
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import BodyState

T0 = 1_700_000_000 * 10**9
MIB = 1024 * 1024


@pytest.fixture
def base(sessions: Path) -> Base:
    """Schemas, channels and metadata of a real recording (two seconds of body states)."""
    items = [(C.BODY_STATE, example_message(BodyState, t=0.01 * k, nan=False)) for k in range(200)]
    items.append((C.EVENTS, Event(1.0, "operator", "marker", "m", "warning")))
    [path] = record(sessions, items, RecorderConfig(chunk_size=4096), epoch_offset=T0 * 1e-9)
    return Base.of(path)


def body_record(base: Base, k: int, pad: int = 0) -> bytes:
    data = codec.encode(example_message(BodyState, t=0.01 * k, nan=False)) + b" " * pad
    return message_record(base.topic_ids[C.BODY_STATE], T0 + k * 10**7, data)


def padded(base: Base, pad: int, piece: int = MIB) -> Iterator[bytes]:
    """One body state padded with ``pad`` spaces (still valid JSON), in pieces."""
    data = codec.encode(example_message(BodyState, t=0.0, nan=False))
    head = message_record(base.topic_ids[C.BODY_STATE], T0, data)
    yield head[:1] + (22 + len(data) + pad).to_bytes(8, "little") + head[9:]
    while pad > 0:
        yield b" " * min(piece, pad)
        pad -= piece


def peak_while(fn) -> tuple[int, object]:
    """(tracemalloc's peak of bytes allocated while ``fn()`` runs, what it returned or raised)."""
    tracemalloc.start()
    try:
        try:
            out: object = fn()
        except Exception as e:
            out = e
        return tracemalloc.get_traced_memory()[1], out
    finally:
        tracemalloc.stop()


def read_all(path: Path, directory: Path, budget: limits.MemoryBudget | None = None) -> int:
    with SessionParts(path, directory, budget=budget) as s:
        return sum(1 for _ in s.records())


def one_line_error(capsys, argv: list[str]) -> str:
    """The CLI's exit code 2 and its one-line error (no traceback)."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("ucat-console: error: ") and "Traceback" not in err
    return err


def test_a_message_padded_beyond_the_chunk_limit_is_refused_before_anything_is_decompressed(
        base, sessions, capsys):
    path = write(sessions / "padded.mcap", base, [chunk_of(padded(base, 200 * MIB), T0, T0, content_size=False)])
    assert path.stat().st_size < 1 * MIB  # 200 MB of message in a small file
    peak, err = peak_while(lambda: SessionReader(path, sessions))
    assert isinstance(err, ValueError) and str(path) in str(err)
    assert "over the limit of 8388608 (review.max_chunk)" in str(err)
    assert peak < 2 * MIB
    err = one_line_error(capsys, ["sessions", "export", str(path), "--topics", "all",
                                  "--out", str(sessions / "csv"), "--dir", str(sessions)])
    assert "review.max_chunk" in err


@pytest.mark.parametrize("compression, content_size", [("zstd", True), ("zstd", False), ("lz4", True)])
def test_a_chunk_that_decompresses_to_more_than_it_declares_is_refused_within_what_it_declares(
        base, sessions, compression, content_size):
    big = chunk_of(padded(base, 64 * MIB), T0, T0 + 10**9, compression, content_size)
    lie = CraftedChunk(big.data, 4096, big.crc, compression, T0, T0 + 10**9)  # header and index: 4 kB
    path = write(sessions / "lie.mcap", base, [lie])
    budget = limits.MemoryBudget()
    with SessionReader(path, sessions, budget=budget) as r:  # the index is within the limits: the file opens
        peak, err = peak_while(lambda: list(r.records()))
    assert isinstance(err, ValueError) and "the chunk at byte" in str(err) and str(path) in str(err)
    assert "4096" in str(err)
    assert peak < 2 * MIB + len(big.data)
    assert budget.used == 0


def test_a_message_over_the_message_limit_is_refused_before_it_is_decoded(base, sessions):
    chunk = chunk_of([body_record(base, 0), b"".join(padded(base, 2 * MIB))], T0, T0 + 1)
    path = write(sessions / "big.mcap", base, [chunk])
    with SessionReader(path, sessions) as r:
        with pytest.raises(ValueError, match=r"channel 'body/state', message at \d+ ns: \d+ bytes, "
                                             r"over the limit of 1048576 \(review.max_message\)"):
            list(r.records())


def test_overlapping_chunks_are_read_within_the_memory_cap(base, sessions):
    """Chunks that all claim the same time must all be read before the first message: the
    reading stops at the cap, gives back what it held, and the file can be read again once
    the cap is raised."""
    budget = limits.MemoryBudget(limits.ReviewConfig(max_chunk=4 * MIB, memory=16 * MIB))
    n = 12
    chunks = [chunk_of([body_record(base, 100 + i, pad=512 * 1024) for i in range(6)], T0, T0 + 10**9)
              for _ in range(n)]  # about 3 MiB each, 36 MiB in all
    path = write(sessions / "overlap.mcap", base, chunks)
    peak, err = peak_while(lambda: read_all(path, sessions, budget))
    assert isinstance(err, limits.MemoryExceeded) and "review.memory" in str(err) and str(path) in str(err)
    assert budget.used == 0 and budget.peak <= 16 * MIB
    assert peak < 16 * MIB + 4 * MIB  # what the cap counts, and a chunk being parsed
    assert read_all(path, sessions, limits.MemoryBudget(limits.ReviewConfig(max_chunk=4 * MIB, memory=64 * MIB))) \
        == 6 * n


def test_json_nested_100k_deep_is_refused_with_a_one_line_error(base, sessions, capsys):
    data = (b'{"t": 1.0, "source": "x", "code": "y", "message": "m", "level": "info", "data": {"d": '
            + b"[" * 100_000 + b"]" * 100_000 + b"}}")
    chunk = chunk_of([message_record(base.topic_ids[C.EVENTS], T0 + 10**9, data)], T0 + 10**9, T0 + 10**9)
    path = write(sessions / "deep.mcap", base, [chunk])
    with SessionParts(path, sessions) as s, pytest.raises(ValueError, match="nests deeper than 64 levels"):
        s.events()
    err = one_line_error(capsys, ["sessions", "export", str(path), "--topics", "events",
                                  "--out", str(sessions / "csv"), "--dir", str(sessions)])
    assert str(path) in err and "deeper than 64" in err
    # nested within Python's recursion limit: refused all the same
    shallow = data.replace(b"[" * 100_000 + b"]" * 100_000, b"[" * 500 + b"]" * 500)
    path = write(sessions / "deep2.mcap", base, [chunk_of([message_record(
        base.topic_ids[C.EVENTS], T0 + 10**9, shallow)], T0 + 10**9, T0 + 10**9)])
    with SessionParts(path, sessions) as s, pytest.raises(ValueError, match="Event.data: nested deeper than 64"):
        s.events()


def test_chunk_indexes_and_footers_that_lie_are_refused(base, sessions):
    good = chunk_of([body_record(base, k) for k in range(10)], T0, T0 + 10**8)
    path = write(sessions / "ok.mcap", base, [good])
    assert read_all(path, sessions) == 10
    data = path.read_bytes()
    with SessionReader(path, sessions) as r:
        ci = r._summary.chunk_indexes[0]

    def variant(name: str, chunk: CraftedChunk, **kw) -> Path:
        return write(sessions / f"{name}.mcap", base, [chunk], **kw)

    # the index says another size than the chunk's header
    liar = variant("index", CraftedChunk(**{**good.__dict__, "index_uncompressed_size": good.uncompressed_size + 1}))
    with SessionReader(liar, sessions) as r, pytest.raises(ValueError, match="not the chunk its index describes"):
        list(r.records())
    # a bad CRC
    crc = variant("crc", CraftedChunk(**{**good.__dict__, "crc": good.crc ^ 1}))
    with SessionReader(crc, sessions) as r, pytest.raises(ValueError, match="corrupted data: its CRC"):
        list(r.records())
    # the summary starts at a chunk (a 200 MB one): refused, nothing decompressed
    bomb = variant("bomb", chunk_of(padded(base, 200 * MIB), T0, T0, content_size=False))
    with open(bomb, "rb") as fh:
        at = make_reader(fh).get_summary().chunk_indexes[0].chunk_start_offset
    summary_at_chunk = variant("summary", chunk_of(padded(base, 200 * MIB), T0, T0, content_size=False),
                               summary_start=at)
    peak, err = peak_while(lambda: SessionReader(summary_at_chunk, sessions))
    assert isinstance(err, TruncatedSessionError) and "a Chunk record in the summary section" in str(err)
    assert peak < 2 * MIB
    # the footer puts the summary beyond the file
    beyond = variant("beyond", good, summary_start=10**12)
    with pytest.raises(ValueError, match="its footer puts the summary at byte 1000000000000"):
        SessionReader(beyond, sessions)
    # an index puts the chunk beyond the file's end
    cut = sessions / "shortened.mcap"
    cut.write_bytes(data[: ci.chunk_start_offset + 20] + data[ci.chunk_start_offset + ci.chunk_length:])
    with pytest.raises(ValueError, match="corrupted"):
        read_all(cut, sessions)
    # truncated: no footer
    (sessions / "trunc.mcap").write_bytes(data[: len(data) // 2])
    with pytest.raises(TruncatedSessionError, match="sessions repair"):
        SessionReader(sessions / "trunc.mcap", sessions)


def test_a_truncated_file_gives_a_one_line_error(base, sessions, capsys):
    good = write(sessions / "ok.mcap", base, [chunk_of([body_record(base, k) for k in range(10)], T0, T0 + 10**8)])
    cut = sessions / "cut.mcap"
    cut.write_bytes(good.read_bytes()[:300])
    err = one_line_error(capsys, ["sessions", "info", str(cut), "--dir", str(sessions)])
    assert str(cut) in err and "sessions repair" in err


def test_the_folder_listing_skips_symlinks_out_of_it_pipes_and_odd_names(base, sessions, tmp_path, capsys):
    outside = tmp_path / "outside.mcap"
    outside.write_bytes(b"not yours")
    os.symlink(outside, sessions / "evil_001.mcap")
    os.symlink(sessions / "nowhere.mcap", sessions / "dangling_001.mcap")
    os.mkfifo(sessions / "pipe_001.mcap")  # opening it would wait for a writer for ever
    (sessions / "dir.mcap").mkdir()
    (sessions / "bad\x1b[31mname_001.mcap").write_bytes(b"x")
    listing = index.scan(sessions)
    why = {s.name: s.why for s in listing.skipped}
    assert "a symbolic link out of the sessions directory" in why["evil_001.mcap"]
    assert "not followed" in why["evil_001.mcap"]
    assert "not a regular file" in why["pipe_001.mcap"] and "not a regular file" in why["dir.mcap"]
    assert "not printable" in why["bad\\x1b[31mname_001.mcap"]
    assert why["dangling_001.mcap"]
    assert len(listing.sessions) == 1 and not listing.sessions[0].parts[0].error
    assert main(["sessions", "list", "--dir", str(sessions)]) == 0
    out = capsys.readouterr().out
    assert "skipped evil_001.mcap: a symbolic link out of the sessions directory" in out
    assert "\x1b" not in out
    with pytest.raises(ValueError, match="outside the sessions directory"):
        SessionParts("evil_001.mcap", sessions)
    # a review marker sidecar that links out of the folder is not followed either
    sid = listing.sessions[0].session_id
    os.symlink(outside, sessions / f"{sid}.markers.json")
    with pytest.raises(ValueError, match="symbolic link out of the sessions directory: not followed"):
        from ucat_console.backend.sessions.markers import MarkerStore
        MarkerStore(sessions, sid)


def test_pages_opening_one_session_share_one_reader(base, sessions):
    path = write(sessions / "s.mcap", base, [chunk_of([body_record(base, k) for k in range(10)], T0, T0 + 10**8)])
    readers = shared.SharedReaders()
    a = readers.acquire("s.mcap", sessions)
    b = readers.acquire(path, sessions)  # by a part file: the same files
    assert a is b and readers.users(a) == 2
    held = readers.budget.used
    assert held > 0  # the summary and metadata, counted once
    alone = limits.MemoryBudget()
    SessionParts(path, sessions, budget=alone).close()
    assert alone.peak == held  # as much as one reader holds
    readers.release(a)
    assert sum(1 for _ in b.records()) == 10  # the other page still reads it
    readers.release(b)
    assert readers.users(a) == 0 and readers.budget.used == 0
    with pytest.raises(ValueError):
        next(a.records())  # closed
