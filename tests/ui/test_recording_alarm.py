"""A failed recording is an alarm: the status bar, every page's notification, the
recording failsafe (warn by default, hold when configured), a file that repairs up to the
fault, and recording started again once there is space.

The disk fills in two ways: a file whose writes fail with ENOSPC past a byte budget (always
runs), and a real full tmpfs mounted as the sessions folder (as root only)."""

from __future__ import annotations

import errno
import io
import os
import shutil
import subprocess
from pathlib import Path

import pytest
from support import Console, wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.backend.sessions import recorder as recorder_module
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.backend.sessions.repair import needs_repair, repair
from ucat_console.backend.supervisor import CommandRefused, Supervisor
from ucat_console.bench.raw_page import RawPage
from ucat_console.backend.access import AccessConfig
from ucat_console.backend.failsafe_config import FailsafeConfig, FailsafeRule
from ucat_console.config import AppConfig
from ucat_console.telemetry import channels as ch
from ucat_console.ui.app import ConsoleApp
from ucat_console.ui.status_bar import bar_state

TOKEN = "pool-side-token"


def run_until_failed(sup: Supervisor, timeout: float = 120.0) -> None:
    """Run the loop (simulated time, as fast as it goes) until the recorder has failed."""
    def step() -> str:
        sup.step(0.1)
        return sup.recording.failed
    wait_for(step, timeout=timeout, what="the recording to fail")
    sup.step(0.1)  # the failsafes are checked between chunks


def events_of(sup: Supervisor) -> list:
    seen: list = []
    sup.stream.subscribe(lambda c, m: seen.append(m), [ch.EVENTS])
    return seen


def check_the_file(path: Path, directory: Path, kept_until: float, bodies: list) -> None:
    """The part repairs, and holds every body state published before ``kept_until`` (the
    latest message time in its complete chunks: messages of that same tick published after
    it may be missing)."""
    assert needs_repair(path)
    report = repair(path, directory)
    assert report.repaired and report.messages > 0
    with SessionReader(path, directory) as r:
        times = [m.t for _, m in r.messages([ch.BODY_STATE])]
    want = [b.t for b in bodies if b.t < kept_until]
    assert want and times[: len(want)] == want
    assert kept_until > 0.0


def test_a_full_disk_raises_the_alarm_everywhere_and_recording_starts_again(tmp_path: Path, monkeypatch) -> None:
    room = {"bytes": 200_000}  # what each new file may hold before the disk is full

    class FullDisk(io.FileIO):
        def write(self, b) -> int:  # type: ignore[override]
            left = room["bytes"] - self.tell()
            if left <= 0:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            return super().write(bytes(b)[:left])

    monkeypatch.setattr(recorder_module, "open",
                        lambda path, mode: io.BufferedWriter(FullDisk(path, mode.replace("b", ""))), raising=False)
    cfg = AppConfig(access=AccessConfig(token=TOKEN), failsafe=FailsafeConfig(recording=FailsafeRule("hold", 0.0)))
    sup = Console(cfg, tmp_path).sup
    app = ConsoleApp(sup, port=0)
    app.start()
    pages: list[RawPage] = []
    try:
        events = events_of(sup)
        bodies: list = []
        sup.stream.subscribe(lambda c, m: bodies.append(m), [ch.BODY_STATE])
        pages = [RawPage(app.url), RawPage(app.url)]
        for p in pages:
            p.wait_for("Arm motors")
        pages[0].take_control(TOKEN)
        wait_for(lambda: sup.access.pilot is not None, what="the pilot")
        pilot = sup.access.pilot
        sup.set_setpoints(pilot, velocity=0.2)
        sup.start_recording(pilot)
        sup.arm(pilot)
        run_until_failed(sup)

        [failed] = [e for e in events if e.code == "write_failed"]
        assert failed.source == "recorder" and failed.level == "error"
        assert "No space left on device" in failed.message and "sessions repair" in failed.message
        # the status bar, the health line, the Session tab
        assert not sup.recorder.recording and "No space left" in sup.recording.failed
        bar = bar_state(sup.state(), None, dark=True, uuids={})
        assert bar["recording"] == "" and "No space left" in bar["recording_failed"]
        assert "recording" in bar["failsafes"]
        [light] = [x for x in bar["lights"] if x["name"] == "Recording"]
        assert light["state"] == "bad" and "FAILED" in light["why"]
        assert "rec=FAILED" in sup.health().line()
        # the failsafe holds: stopped where it is, setpoints refused until the operator acts
        assert sup.safety.is_active("recording") and sup.setpoints.velocity == 0.0
        with pytest.raises(CommandRefused, match="recording"):
            sup.set_setpoints(pilot, velocity=0.2)
        # every page is notified
        for p in pages:
            wait_for(lambda p=p: any("recording failed" in n for n in p.notifications), what="the notification")
        # the disarm does not bring the recording back to life
        sup.disarm(pilot)
        sup.step(0.2)
        assert not sup.recorder.recording and sup.recording.failed

        check_the_file(sup.recorder.paths[-1], tmp_path, failed.data["kept_until"], bodies)

        # space again: recording starts again (a new session), the failsafe clears
        room["bytes"] = 10**9
        first = sup.recorder.session_id
        sup.start_recording(pilot)
        assert sup.recorder.recording and sup.recorder.session_id != first and not sup.recording.failed
        sup.step(0.2)
        assert not sup.safety.is_active("recording")
        assert any(e.code == "failure_cleared" for e in events)
        sup.set_setpoints(pilot, velocity=0.1)
        for p in pages:
            wait_for(lambda p=p: any("recording again" in n for n in p.notifications), what="the all-clear")
        [path] = sup.stop_recording(pilot)
        with SessionReader(path, tmp_path) as r:
            assert r.message_count > 0
    finally:
        for p in pages:
            p.close()
        app.stop()
        sup.stop()


def test_a_failure_is_acknowledged_by_stopping(tmp_path: Path, monkeypatch) -> None:
    """The default rule warns; Stop recording acknowledges the failure and clears it."""
    class NoRoom(io.FileIO):
        def write(self, b) -> int:  # type: ignore[override]
            if self.tell() > 50_000:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            return super().write(b)

    monkeypatch.setattr(recorder_module, "open",
                        lambda path, mode: io.BufferedWriter(NoRoom(path, mode.replace("b", ""))), raising=False)
    sup = Console(AppConfig(), tmp_path).sup
    try:
        sup.set_setpoints(LOCAL, velocity=0.2)
        sup.arm(LOCAL)  # records from arming
        run_until_failed(sup)
        assert sup.safety.is_active("recording") and sup.setpoints.velocity == 0.2  # warn only
        sup.stop_recording(LOCAL)
        sup.step(0.2)
        assert not sup.recording.failed and not sup.safety.is_active("recording")
        with pytest.raises(CommandRefused, match="not recording"):
            sup.stop_recording(LOCAL)
    finally:
        sup.stop()


def _mount_tmpfs(where: Path, size: str) -> bool:
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                       capture_output=True, text=True)
    return r.returncode == 0


@pytest.mark.slow
def test_a_full_tmpfs_sessions_folder_raises_the_alarm_and_leaves_a_readable_file(tmp_path: Path) -> None:
    folder = tmp_path / "sessions"
    folder.mkdir()
    if not _mount_tmpfs(folder, "2m"):
        pytest.skip("mounting a tmpfs needs root and mount(8)")
    try:
        filler = folder / "filler"
        filler.write_bytes(b"\0" * (2 * 1024 * 1024 - 400 * 1024))  # 400 kB left for the recording
        sup = Console(AppConfig(), folder).sup
        try:
            events = events_of(sup)
            bodies: list = []
            sup.stream.subscribe(lambda c, m: bodies.append(m), [ch.BODY_STATE])
            sup.set_setpoints(LOCAL, velocity=0.2)
            sup.arm(LOCAL)
            run_until_failed(sup)
            [failed] = [e for e in events if e.code == "write_failed"]
            assert "ENOSPC" in failed.data["error"] or "No space left" in failed.data["error"]
            assert sup.safety.is_active("recording") and not sup.recorder.recording
            assert "recording" in bar_state(sup.state(), None, dark=True, uuids={})["failsafes"]
            filler.unlink()  # space returns
            check_the_file(sup.recorder.paths[-1], folder, failed.data["kept_until"], bodies)
            sup.start_recording(LOCAL)
            sup.step(0.5)
            assert sup.recorder.recording and not sup.safety.is_active("recording")
        finally:
            sup.stop()
    finally:
        subprocess.run(["umount", str(folder)], check=False)
        if os.path.ismount(folder):
            subprocess.run(["umount", "-l", str(folder)], check=False)
