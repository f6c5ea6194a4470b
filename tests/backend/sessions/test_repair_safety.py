"""A repair never touches a file a recorder is writing (in this process, or from a shell
beside a recording process), and never hides data: the original is kept, unchanged, beside
the repaired file, and listed."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest
from session_helpers import record

from support import wait_for
from ucat_console.backend.sessions import index, writing
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.sessions.recorder import Recorder, RecorderConfig
from ucat_console.backend.sessions.repair import needs_repair, repair
from ucat_console.cli import main
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.messages import Setpoints
from ucat_console.telemetry.stream import TelemetryStream

CHILD = r"""
import sys
from ucat_console.backend.sessions.recorder import Recorder, RecorderConfig
from ucat_console.telemetry.messages import Setpoints
from ucat_console.telemetry.stream import TelemetryStream
stream = TelemetryStream()
rec = Recorder(stream, RecorderConfig(flush_interval=0.05), directory=sys.argv[1])
rec.start(label="shell")
for k in range(200):
    stream.publish("body/setpoints", Setpoints(0.01 * k, float(k), 1.0, 0.0))
print(rec.paths[0], flush=True)
sys.stdin.read()  # recording until killed
"""


def publish(stream: TelemetryStream, ks: range) -> None:
    for k in ks:
        stream.publish(C.SETPOINTS, Setpoints(0.01 * k, float(k), 1.0, 0.0))


def test_the_part_being_recorded_is_refused_and_the_recording_completes(sessions: Path) -> None:
    stream = TelemetryStream()
    rec = Recorder(stream, RecorderConfig(flush_interval=0.05), directory=sessions)
    rec.start(label="live")
    try:
        [path] = rec.paths
        publish(stream, range(500))
        wait_for(lambda: rec.stats().written == 500 and path.stat().st_size > 0, what="the first messages written")
        assert needs_repair(path)  # no summary yet: what the Review tab offers to repair
        with pytest.raises(ValueError, match=f"repair: {path.name} is being recorded; stop the recording first"):
            repair(path, sessions)
        [info] = index.list_sessions(sessions)
        assert info.recording and info.parts[0].recording and not info.parts[0].repairable
        publish(stream, range(500, 1000))
    finally:
        rec.stop()
    assert [p.name for p in sessions.iterdir()] == [path.name]  # no original, no temporary copy
    with SessionReader(path, sessions) as r:
        assert [m.velocity for _, m in r.messages()] == [float(k) for k in range(1000)]
    assert not writing.being_written(path)
    assert not index.list_sessions(sessions)[0].recording


def test_a_shell_repair_beside_a_recording_process_is_refused_until_the_recorder_is_gone(
        sessions: Path, capsys: pytest.CaptureFixture[str]) -> None:
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(sessions)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        path = Path(proc.stdout.readline().strip())
        assert path.name.endswith("-shell_001.mcap"), path
        wait_for(lambda: path.stat().st_size > 1000, what="the child's first chunks")
        assert main(["sessions", "repair", str(path), "--dir", str(sessions)]) == 2
        err = capsys.readouterr().err
        assert f"repair: {path.name} is being recorded; stop the recording first" in err
        assert not path.with_name(path.stem + ".orig.mcap").exists()
        [info] = index.list_sessions(sessions)  # the listing says so too
        assert info.recording
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    # the lock went with the process: the killed recording repairs
    assert main(["sessions", "repair", str(path), "--dir", str(sessions)]) == 0
    assert f"original kept as {path.with_name(path.stem + '.orig.mcap')}" in capsys.readouterr().out


def test_the_original_is_kept_unchanged_and_listed_beside_the_repaired_file(
        sessions: Path, capsys: pytest.CaptureFixture[str]) -> None:
    items = [(C.SETPOINTS, Setpoints(0.01 * k, float(k), 1.0, 0.0)) for k in range(3000)]
    [path] = record(sessions, items, RecorderConfig(chunk_size=4096))
    path.write_bytes(path.read_bytes()[:20_000])  # a killed recorder: no summary
    cut = path.read_bytes()
    report = repair(path, sessions)
    original = sessions / (path.stem + ".orig.mcap")
    assert report.repaired and report.original == original and original.read_bytes() == cut

    listing = index.scan(sessions)
    assert not listing.skipped
    parts = {p.path.name: p for s in listing.sessions for p in s.parts}
    assert set(parts) == {path.name, original.name}
    assert not parts[path.name].truncated and parts[path.name].messages > 0
    kept = parts[original.name]
    assert kept.truncated and kept.original_of == path.name and not kept.repairable
    assert main(["sessions", "list", "--dir", str(sessions)]) == 0
    assert f"[the original of {path.name}, kept by its repair]" in capsys.readouterr().out

    with pytest.raises(ValueError, match="a repair never rewrites it"):
        repair(original, sessions, force=True)
    assert not repair(path, sessions).repaired  # the repaired file opens
    assert original.read_bytes() == cut
