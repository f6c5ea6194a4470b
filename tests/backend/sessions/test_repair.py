"""Crash safety: a recorder killed with SIGKILL, the truncated file, and its repair."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import breakup_chunk
from session_helpers import record

from ucat_console.backend.sessions.index import list_sessions
from ucat_console.backend.sessions.mcap_read import TruncatedSessionError
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.sessions.recorder import RecorderConfig
from ucat_console.backend.sessions.repair import repair
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.messages import Setpoints

RATE = 1000  # messages per second in the child
BATCH = 10  # messages per publish burst (every BATCH / RATE s)

CHILD = r"""
import sys, time
from ucat_console.backend.sessions.recorder import Recorder
from ucat_console.telemetry.messages import Setpoints
from ucat_console.telemetry.stream import TelemetryStream
directory, rate, batch = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
stream = TelemetryStream()
rec = Recorder(stream, directory=directory)
rec.start(label="killed", notes="recorded until SIGKILL")
print("started", rec.paths[0], flush=True)
k = 0
t0 = time.monotonic()
while True:
    for _ in range(batch):
        stream.publish("body/setpoints", Setpoints(k / rate, float(k), 1.0, 0.0))
        k += 1
    print(k, flush=True)
    time.sleep(max(0.0, t0 + k / rate - time.monotonic()))
"""


def _sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_sigkill_loses_at_most_about_a_second_and_repair_recovers_the_rest(sessions):
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(sessions), str(RATE), str(BATCH)],
        stdout=subprocess.PIPE, text=True,
    )
    try:
        first = proc.stdout.readline().split()
        assert first[0] == "started", first
        path = Path(first[1])
        published = 0
        deadline = time.monotonic() + 60.0
        while published < 2.5 * RATE:  # record for about 2.5 s
            assert time.monotonic() < deadline, "child too slow"
            line = proc.stdout.readline()
            assert line, "child died"
            published = int(line)
        proc.send_signal(signal.SIGKILL)
        for line in proc.stdout:  # counts printed before the kill
            published = int(line)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == -signal.SIGKILL

    # the plain mcap reader cannot use it, ours refuses it and names the repair
    with open(path, "rb") as fh, pytest.raises(Exception):
        list(make_reader(fh).iter_messages())
    with pytest.raises(TruncatedSessionError, match="sessions repair"):
        SessionReader(path, sessions)
    [info] = list_sessions(sessions)
    assert info.truncated and info.notes == "recorded until SIGKILL"
    before = _sha(path)

    report = repair(path, sessions)
    assert report.repaired and report.original == path.with_name(path.stem + ".orig.mcap")
    assert _sha(report.original) == before  # the original is kept as it was
    with SessionReader(path, sessions) as r:
        values = [m.velocity for _, m in r.messages()]
        assert r.notes == "recorded until SIGKILL"
    with open(path, "rb") as fh:  # every message of the file, the derived Foxglove ones too
        assert report.messages == sum(1 for _ in make_reader(fh).iter_messages())
    assert len(values) > 0
    assert values == [float(k) for k in range(len(values))]  # a prefix: only the tail lost
    # the child published at least ``published`` and at most one burst more
    lost_at_most = published + BATCH - len(values)
    print(f"published {published}..{published + BATCH}, recovered {len(values)}")
    assert lost_at_most <= RATE, f"lost up to {lost_at_most} of {published} messages"
    # a second repair finds nothing to do
    assert not repair(path, sessions).repaired


def test_repair_of_a_cut_file_recovers_every_complete_chunk(sessions):
    items = [(C.SETPOINTS, Setpoints(0.01 * k, float(k), 1.0, 0.0)) for k in range(5000)]
    [path] = record(sessions, items, RecorderConfig(chunk_size=4096))
    with SessionReader(path, sessions) as r:
        chunks = sorted(r._summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
        setpoints_id = r._topic_ids[C.SETPOINTS]
    cut = chunks[len(chunks) // 2].chunk_start_offset + 7  # inside a chunk record
    # independently: the messages of the chunks that end before the cut (all of them, and
    # the setpoints among them; the others are the derived Foxglove scene and transform)
    expected = setpoints = 0
    with open(path, "rb") as fh:
        for ci in chunks:
            if ci.chunk_start_offset + ci.chunk_length <= cut:
                fh.seek(ci.chunk_start_offset + 9)  # past opcode and length
                chunk = Chunk.read(ReadDataStream(fh))
                messages = [x for x in breakup_chunk(chunk) if isinstance(x, Message)]
                expected += len(messages)
                setpoints += sum(x.channel_id == setpoints_id for x in messages)
    path.write_bytes(path.read_bytes()[:cut])
    report = repair(path, sessions, keep_original=False)
    assert report.messages == expected > 0
    assert report.original is None and not path.with_name(path.stem + ".orig.mcap").exists()
    assert report.stop_reason  # it says where reading broke off
    with SessionReader(path, sessions) as r:
        assert [m.velocity for _, m in r.messages()] == [float(k) for k in range(setpoints)]
        assert set(r.channels) == set(C.CHANNELS)  # schemas and channels came along


def test_repair_refuses_what_it_cannot_repair(sessions, tmp_path):
    text = sessions / "x.mcap"
    text.write_text("hello")
    with pytest.raises(ValueError, match="not an MCAP file"):
        repair(text, sessions)
    with pytest.raises(ValueError, match="outside the sessions directory"):
        repair(tmp_path / "y.mcap", sessions)
    with pytest.raises(ValueError, match="no such session file"):
        repair(sessions / "missing.mcap", sessions)
    assert not os.path.exists(sessions / "x.orig.mcap")
