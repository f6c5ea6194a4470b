"""`bench library`'s parts run on a small folder and say what they timed (no timing asserted)."""

from __future__ import annotations

from pathlib import Path

from ucat_console.backend.sessions.library import Library
from ucat_console.bench.library import FILTER, cold_read, warm_index


def test_the_warm_index_holds_every_row_and_the_filter_matches_what_the_rows_say(tmp_path: Path) -> None:
    d = tmp_path / "warm"
    d.mkdir()
    out = warm_index(d, 40, 1)
    assert out["listed"] == out["unchanged"] == 40
    with Library(d) as lib:
        rows = lib.find("")
        expected = [r.id for r in rows if "mpc" in r.modes and (r.figures["speed"] or 0) > 0.15
                    and "pool-3" in r.tags and r.date >= "2026-12-01" and "weak fin" in r.notes]
        assert sorted(r.id for r in lib.find(FILTER)) == sorted(expected)
        assert out["matched"] == len(expected)


def test_a_cold_session_is_read_with_its_figures(tmp_path: Path) -> None:
    out = cold_read(tmp_path, 1, 5.0)
    assert out["added"] == 1
    with Library(tmp_path) as lib:
        [row] = lib.find("")
        assert row.status == "ok" and row.figures["epm"] is not None and row.figures["st_in"] is not None
