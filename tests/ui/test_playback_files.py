"""The review panel and untrusted files: pages opening one session share one reader; a
file refused on opening, or a playback stopped by a damaged chunk further on, is shown on
the page."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import pytest
import viser
from support import wait_for

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "backend" / "sessions"))
from crafted import Base, chunk_of, message_record, write  # noqa: E402
from session_helpers import example_message, record  # noqa: E402

from ucat_console.backend.sessions import codec, shared  # noqa: E402
from ucat_console.backend.sessions.recorder import RecorderConfig  # noqa: E402
from ucat_console.config import AppConfig  # noqa: E402
from ucat_console.telemetry import channels as ch  # noqa: E402
from ucat_console.telemetry.messages import BodyState  # noqa: E402
from ucat_console.ui.playback import PlaybackPanel  # noqa: E402

T0 = 1_700_000_000 * 10**9


@pytest.fixture
def server():
    s = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield s
    s.stop()


def panel(server: viser.ViserServer, directory: Path, readers: shared.SharedReaders | None = None) -> PlaybackPanel:
    return PlaybackPanel(server.gui, server.scene, AppConfig().plant.geometry, directory=directory, readers=readers)


def bodies(base: Base, ks: range) -> list[bytes]:
    return [message_record(base.topic_ids[ch.BODY_STATE], T0 + k * 10**7,
                           codec.encode(example_message(BodyState, t=0.01 * k, nan=False))) for k in ks]


@pytest.fixture
def recorded(tmp_path: Path) -> tuple[Path, str, Base]:
    d = tmp_path / "sessions"
    d.mkdir()
    items = [(ch.BODY_STATE, example_message(BodyState, t=0.01 * k, nan=False)) for k in range(100)]
    [path] = record(d, items, RecorderConfig(chunk_size=4096), epoch_offset=T0 * 1e-9)
    return d, path.name.split("_")[0], Base.of(path)


def test_two_pages_opening_one_session_share_its_reader(server, recorded) -> None:
    d, sid, _ = recorded
    readers = shared.SharedReaders()  # the console's
    a, b = panel(server, d, readers), panel(server, d, readers)
    try:
        assert a.act(lambda: a.open(sid)) and b.act(lambda: b.open(sid))
        assert a.reader is b.reader and readers.users(a.reader) == 2
        a.close_session()
        assert readers.users(b.reader) == 1
        assert b.act(lambda: b.seek(0.5)) and b.player.position > b.player.start
        reader = b.reader
        b.close_session()
        assert readers.users(reader) == 0 and readers.budget.used == 0
    finally:
        a.stop()
        b.stop()


def test_a_refused_file_and_a_playback_failure_are_shown_on_the_page(server, recorded) -> None:
    d, _, base = recorded
    bad = write(d / "bad.mcap", base, [chunk_of([b"\x01\x00"], T0, T0)])  # a record cut short
    p = panel(server, d)
    try:
        assert not p.act(lambda: p.open("bad.mcap"))
        assert "bad.mcap" in p.messages[-1] and "corrupted data" in p.messages[-1]
        assert "Refused" in p.message.content
        # a damaged chunk after a second of good ones: the session opens, playing stops there
        body = base.topic_ids[ch.BODY_STATE]
        first = replace(chunk_of(bodies(base, range(0, 50)), T0, T0 + 49 * 10**7), index_channels=(body,))
        damaged = chunk_of(bodies(base, range(50, 100)), T0 + 50 * 10**7, T0 + 99 * 10**7)
        damaged = replace(damaged, crc=damaged.crc ^ 1, index_channels=(body,))
        write(d / "late.mcap", base, [first, damaged])
        assert p.act(lambda: p.open("late.mcap")), p.messages
        p.set_speed(5.0)
        p.play()
        wait_for(lambda: any("playback stopped" in m for m in p.messages), timeout=30.0, what="the failure shown")
        shown = next(m for m in p.messages if "playback stopped" in m)
        assert "late.mcap" in shown and "CRC" in shown and not p.player.playing
        p._sync_inputs()
        assert "stopped on an error" in p.status.content
    finally:
        p.stop()


def test_the_review_list_says_which_entries_it_did_not_read(server, recorded, tmp_path: Path) -> None:
    d, sid, _ = recorded
    outside = tmp_path / "elsewhere.mcap"
    outside.write_bytes(b"not read")
    (d / "link.mcap").symlink_to(outside)
    (d / "folder.mcap").mkdir()
    p = panel(server, d)
    try:
        sessions = p.refresh_sessions()
        assert [s.session_id for s in sessions] == [sid]
        text = p.browser.content
        assert sid in text
        assert "not read: link.mcap: a symbolic link out of the sessions directory" in text
        assert "not read: folder.mcap: not a regular file" in text
    finally:
        p.stop()


def test_a_page_cannot_open_a_session_file_outside_the_sessions_folder(server, recorded, tmp_path: Path) -> None:
    """The shell reads a file wherever the user names it; a page stays in the sessions folder:
    its panel takes names only, and the readers it opens through refuse a path outside."""
    from ucat_console.backend.sessions.reader import SessionParts

    d, sid, _ = recorded
    away = tmp_path / "away"
    away.mkdir()
    moved = away / f"{sid}_001.mcap"
    moved.write_bytes((d / moved.name).read_bytes())
    p = panel(server, d)
    try:
        assert not p.act(lambda: p.open(str(moved)))
        assert "is not a session or a file name" in p.messages[-1] and p.reader is None
    finally:
        p.stop()
    for open_it in (lambda: shared.SharedReaders().acquire(moved, d), lambda: SessionParts(moved, d)):
        with pytest.raises(ValueError, match="outside the sessions directory"):
            open_it()
    with SessionParts(moved, d, confined=False) as s:  # what the command line opens
        assert s.session_id == sid
