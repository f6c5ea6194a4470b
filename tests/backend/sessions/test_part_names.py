"""The parts of a session are decided by file names (the recorder's ``<id>_<part>.mcap``),
never by what a file's metadata claims, and a symbolic link is never read as a part."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from session_helpers import record

from ucat_console.backend.sessions import files, index
from ucat_console.backend.sessions.files import part_paths
from ucat_console.backend.sessions.reader import SessionParts
from ucat_console.backend.sessions.recorder import RecorderConfig
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.messages import Setpoints

WALL = 1_700_000_000.0
SPLIT = RecorderConfig(split_duration=1.0, chunk_size=4096)


def setpoints(n: int, t0: float = 0.0) -> list[tuple[str, Setpoints]]:
    return [(C.SETPOINTS, Setpoints(t0 + 0.1 * k, float(k), 1.0, 0.0)) for k in range(n)]


def listed(directory: Path) -> dict[str, list[str]]:
    """session -> the names of its listed parts, in order."""
    return {s.session_id: [p.path.name for p in s.parts] for s in index.scan(directory).sessions}


def test_a_file_whose_metadata_claims_a_part_of_another_session_is_listed_by_its_name(sessions, tmp_path):
    [own] = record(sessions, setpoints(5), wall_time=WALL, label="pool")
    sid = files.parse_part_name(own)[0]
    # the same session recorded elsewhere in two parts: its part 2 says "session sid, part 2"
    elsewhere = tmp_path / "elsewhere"
    parts = record(elsewhere, setpoints(30), SPLIT, wall_time=WALL, label="pool")
    assert [files.parse_part_name(p) for p in parts[:2]] == [(sid, 1), (sid, 2)]
    crafted = sessions / "evil.mcap"
    shutil.copy(parts[1], crafted)

    assert listed(sessions) == {sid: [own.name], "evil.mcap": ["evil.mcap"]}
    with SessionParts(sid, sessions) as s:
        assert s.paths == (own,)
    with SessionParts(crafted, sessions) as s:  # read alone, under its own name
        assert s.session_id == "evil.mcap" and s.paths == (crafted,)


def test_a_file_named_as_a_part_whose_metadata_names_another_session_is_marked_and_refused(sessions):
    [a] = record(sessions, setpoints(5), wall_time=WALL, label="a")
    [b] = record(sessions, setpoints(5), wall_time=WALL, label="b")
    sid = files.parse_part_name(a)[0]
    posing = sessions / files.part_name(sid, 2)
    shutil.copy(b, posing)  # named part 2 of a, its metadata says part 1 of b
    [info] = [s for s in index.scan(sessions).sessions if s.session_id == sid]
    assert [p.path.name for p in info.parts] == [a.name, posing.name]
    assert "its metadata names session" in info.parts[1].error and not info.parts[0].error
    with pytest.raises(ValueError, match="its metadata names session"):
        SessionParts(sid, sessions)


def test_a_symbolic_link_in_the_folder_is_never_a_part(sessions):
    [a] = record(sessions, setpoints(5), wall_time=WALL, label="a")
    [b] = record(sessions, setpoints(5), wall_time=WALL, label="b")
    sid_a, sid_b = files.parse_part_name(a)[0], files.parse_part_name(b)[0]
    # a link named as part 2 of a, to b's file; and one named as a session of its own
    os.symlink(b.name, sessions / files.part_name(sid_a, 2))
    os.symlink(b, sessions / "c_001.mcap")

    listing = index.scan(sessions)
    assert {s.session_id: [p.path.name for p in s.parts] for s in listing.sessions} == {
        sid_a: [a.name], sid_b: [b.name]}
    why = {k.name: k.why for k in listing.skipped}
    for name in (files.part_name(sid_a, 2), "c_001.mcap"):
        assert why[name].startswith(f"a symbolic link (to {b.name}): not followed"), why
    assert list(part_paths(sid_a, sessions).values()) == [a]
    with SessionParts(sid_a, sessions) as s:
        assert s.paths == (a,)
    with pytest.raises(ValueError, match="no files"):
        SessionParts("c", sessions)
