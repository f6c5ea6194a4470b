"""Review markers: notes within 2 kB, at most 10,000 a session, the sidecar always whole,
one store per session for every reviewer in the process."""

from __future__ import annotations

import json
import os

import pytest

from ucat_console.backend.sessions.markers import MAX_MARKERS, MAX_NOTE_BYTES, MarkerStore


def test_a_note_is_limited_in_bytes_not_characters(tmp_path):
    store = MarkerStore(tmp_path, "s1")
    store.add(1.0, "x" * MAX_NOTE_BYTES)
    with pytest.raises(ValueError, match=f"over the limit of {MAX_NOTE_BYTES} bytes"):
        store.add(2.0, "x" * (MAX_NOTE_BYTES + 1))
    with pytest.raises(ValueError, match="over the limit"):
        store.add(2.0, "ü" * (MAX_NOTE_BYTES // 2 + 1))  # two bytes each
    with pytest.raises(ValueError, match="expected text"):
        store.add(2.0, 42)  # type: ignore[arg-type]
    assert [m.t for m in MarkerStore(tmp_path, "s1").markers] == [1.0]


def test_a_note_is_counted_as_the_file_stores_it(tmp_path):
    store = MarkerStore(tmp_path, "s4")
    store.add(1.0, "ü" * (MAX_NOTE_BYTES // 2))  # stored as UTF-8, not as \u escapes
    with pytest.raises(ValueError, match="over the limit"):
        store.add(2.0, "\x01" * (MAX_NOTE_BYTES // 6 + 1))  # a control character is stored as \u0001
    with pytest.raises(ValueError, match="over the limit"):
        store.add(2.0, '"' * (MAX_NOTE_BYTES // 2 + 1))  # a quote as \"
    with pytest.raises(ValueError, match="not valid text"):
        store.add(2.0, "\ud800")
    size = store.path.stat().st_size
    assert MAX_NOTE_BYTES <= size < MAX_NOTE_BYTES + 200  # the note as UTF-8, plus the marker's JSON


def test_a_session_keeps_at_most_max_markers(tmp_path):
    path = tmp_path / "s2.markers.json"
    full = [{"t": float(i), "note": "", "created": 0.0} for i in range(MAX_MARKERS)]
    path.write_text(json.dumps({"session": "s2", "markers": full}))
    store = MarkerStore(tmp_path, "s2")
    with pytest.raises(ValueError, match="most markers"):
        store.add(1.5, "one more")
    assert len(json.loads(path.read_text())["markers"]) == MAX_MARKERS
    path.write_text(json.dumps({"session": "s2", "markers": full + full[:1]}))
    with pytest.raises(ValueError, match="more than the limit"):
        MarkerStore(tmp_path, "s2")


def test_a_failed_write_leaves_the_file_and_the_markers_as_they_were(tmp_path, monkeypatch):
    store = MarkerStore(tmp_path, "s3")
    first = store.add(1.0, "kept")
    before = (tmp_path / "s3.markers.json").read_bytes()

    def fail(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OSError, match="disk full"):
        store.add(2.0, "lost")
    assert store.markers == [first]
    assert (tmp_path / "s3.markers.json").read_bytes() == before
    assert not list(tmp_path.glob("*.tmp"))


def test_every_reviewer_in_the_process_shares_one_store(tmp_path):
    a = MarkerStore.shared(tmp_path, "s4")
    b = MarkerStore.shared(tmp_path, "s4")
    assert a is b
    a.add(1.0, "from page a")
    b.add(2.0, "from page b")
    doc = json.loads((tmp_path / "s4.markers.json").read_text())
    assert [m["note"] for m in doc["markers"]] == ["from page a", "from page b"]
