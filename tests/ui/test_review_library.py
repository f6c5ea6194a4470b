"""The Review tab's run list from the run library, driven by raw websocket pages on a served
console: a query filters the list (a bad one is refused with the library's text and the list
stays), tags and notes are written only by the pilot or a page that gave its name and only
when every value passes the server's checks, and the list follows a recording that ends."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import pytest
from support import TOKEN, Console, console_config, wait_for

from ucat_console.backend.access import LOCAL
from ucat_console.backend.sessions import sidecar
from ucat_console.backend.sessions.recorder import Recorder, RecorderConfig
from ucat_console.backend.supervisor.run_library import MAX_TAG_CHANGES, RunLibrary
from ucat_console.telemetry import channels as ch
from ucat_console.telemetry.messages import Setpoints
from ucat_console.telemetry.stream import TelemetryStream
from ucat_console.ui.markdown import esc
from ucat_console.ui.viser_compat import handle_uuid

SETTINGS = {"scene_rate": 10.0, "plot_rate": 2.0}


def recorded(directory: Path, label: str, notes: str) -> str:
    """A short complete session with ``notes``; its id."""
    stream = TelemetryStream()
    rec = Recorder(stream, RecorderConfig(), directory=directory)
    sid = rec.start(label=label, notes=notes)
    for k in range(50):
        stream.publish(ch.SETPOINTS, Setpoints(0.01 * k, 0.1, 1.0, 0.0))
    rec.stop()
    return sid


class Review:
    """A raw page and its Review tab as the console built it (to find its elements' ids)."""

    def __init__(self, console: Console) -> None:
        self.console = console
        self.page = console.page()
        self.cid = console.cid_of(self.page)
        wait_for(lambda: self.cid in console.app.reviews, what="the page's review")
        self.panel = console.app.reviews[self.cid]
        self.runs = self.panel.run_list

    def uuid(self, handle: Any) -> str:
        u = handle_uuid(handle)
        wait_for(lambda: self.page.element(u), what="the element on the page")
        return u

    def options(self) -> tuple[str, ...]:
        """The Session chooser's options as the page has them."""
        return tuple(self.page.element(self.uuid(self.panel.choice)).get("options", ()))

    def send(self, handle: Any, value: Any) -> None:
        self.page.update(self.uuid(handle), value=value)

    def press(self, handle: Any) -> None:
        self.page.update(self.uuid(handle), value=True)

    def refused(self, text: str) -> str:
        wait_for(lambda: any(text in m for m in self.panel.messages), what=f"a message holding {text!r}")
        return next(m for m in self.panel.messages if text in m)

    def choose(self, sid: str) -> None:
        wait_for(lambda: sid in self.options(), what=f"{sid} in the chooser")
        self.send(self.panel.choice, sid)
        wait_for(lambda: self.panel.choice.value == sid and self.runs._filled_for == sid, what=f"{sid} chosen")


@pytest.fixture
def two_runs(tmp_path: Path) -> tuple[str, str]:
    return recorded(tmp_path, "a", "calm water"), recorded(tmp_path, "b", "weak fin 2")


def test_a_query_lists_only_the_matching_runs_and_a_bad_one_changes_nothing(
        make_console: Callable[..., Console], two_runs: tuple[str, str]) -> None:
    a, b = two_runs
    review = Review(make_console(console_config(**SETTINGS), serve=True))
    wait_for(lambda: set(review.options()) == {a, b}, what="both runs listed")
    review.send(review.runs.search, "weak")
    wait_for(lambda: review.options() == (b,), what="only the matching run in the page's chooser")
    table = review.page.element(review.uuid(review.runs.table))
    text = str(table.get("_markdown", table.get("content", "")))
    assert b in text and a not in text

    review.send(review.runs.search, "speed>fast")
    said = review.refused("speed>fast")
    assert "not a finite number" in said  # the library's own text
    assert review.options() == (b,)  # the list stands
    assert review.panel.session.query[0] == "weak"


def test_a_bad_tag_from_a_raw_page_is_refused_and_nothing_is_written(
        make_console: Callable[..., Console], two_runs: tuple[str, str], tmp_path: Path) -> None:
    a, _ = two_runs
    # the pilot page may be slow to answer the console's heartbeats on a loaded machine
    console = make_console(console_config(pilot_gone=30.0, **SETTINGS), serve=True)
    review = Review(console)
    review.page.take_control(TOKEN)
    wait_for(lambda: console.sup.access.pilot == review.cid, what="the page taking control")
    review.choose(a)
    journal = len(console.sup.journal())

    review.send(review.runs.tags, "+pool-3 +bad/tag")
    review.press(review.runs.save_tags)
    assert "'bad/tag'" in review.refused("bad/tag")
    assert not sidecar.path_of(tmp_path, a).exists()  # not even the good one of the two
    assert len(console.sup.journal()) == journal

    review.send(review.runs.tags, "+pool-3")
    review.press(review.runs.save_tags)
    wait_for(lambda: sidecar.read(tmp_path, a).tags == ("pool-3",), what="the tag written")
    wait_for(lambda: [e for e in console.sup.journal() if e.key == f"session {a} tags"], what="the journal")
    wait_for(lambda: any(line.startswith(f"| **{esc(a)}** |") and "| pool-3 |" in line
                         for line in review.runs.table.content.splitlines()), what="the table showing the tag")


def test_a_viewer_without_a_name_cannot_edit_and_with_one_can(
        make_console: Callable[..., Console], two_runs: tuple[str, str], tmp_path: Path) -> None:
    a, _ = two_runs
    console = make_console(console_config(**SETTINGS), serve=True)
    review = Review(console)  # a viewer: not the pilot
    review.choose(a)
    review.send(review.runs.notes, "weak fin 3 after the dive")
    review.press(review.runs.save_notes)
    assert "give your name" in review.refused("give your name")
    assert not sidecar.path_of(tmp_path, a).exists()

    review.page.set_value("Your name", "Kati")
    wait_for(lambda: console.sup.access.name(review.cid) == "Kati", what="the name given")
    review.press(review.runs.save_notes)
    wait_for(lambda: sidecar.read(tmp_path, a).notes == "weak fin 3 after the dive", what="the notes written")
    entry = wait_for(lambda: [e for e in console.sup.journal() if e.key == f"session {a} notes"], what="the journal")
    assert entry[-1].who.startswith("Kati")


def test_the_list_follows_a_recording_that_ends(make_console: Callable[..., Console]) -> None:
    console = make_console(console_config(**SETTINGS), serve=True)
    review = Review(console)
    wait_for(lambda: review.options() == ("",), what="the empty list")
    sup = console.sup
    sid = sup.start_recording(LOCAL)
    wait_for(lambda: sup.recorder.stats().written > 20, what="the recording")
    sup.stop_recording(LOCAL)
    wait_for(lambda: sid in review.options(), what="the ended recording in the page's list", timeout=30.0)


def test_every_value_is_checked_before_anything_is_written(tmp_path: Path) -> None:
    sid = recorded(tmp_path, "a", "")
    runs = RunLibrary(tmp_path)
    try:
        runs.refresh()
        for query, sort, desc in (("", "no_such_field", False), ("", "tag", False), ("", "start", "yes"),
                                  ("x" * 501, "start", False), ("a\nb", "start", False), (None, "start", False)):
            with pytest.raises(ValueError):
                runs.find(query, sort, desc)
        for changes in ("+pool-3", [], ["+ok"] * (MAX_TAG_CHANGES + 1), [3], ["+"], ["+a b"], ["-" + "x" * 65]):
            with pytest.raises(ValueError):
                runs.set_tags(sid, changes)
        for notes in (None, 3, "x" * (sidecar.MAX_NOTES + 1), "bell\x07"):
            with pytest.raises(ValueError):
                runs.set_notes(sid, notes)
        for bad_id in ("../x", "", 5, "a/b"):
            with pytest.raises(ValueError):
                runs.set_tags(bad_id, ["+ok"])
        assert not sidecar.path_of(tmp_path, sid).exists()
        assert runs.set_tags(sid, ["+ok"]) == ((), ("ok",))
        assert runs.set_notes(sid, "line one\nline two")[1].notes == "line one\nline two"
    finally:
        runs.close()


def test_each_run_carries_the_mpc_weights_its_recording_holds(tmp_path: Path) -> None:
    from ucat_console.config import AppConfig

    cfg = AppConfig()
    cfg = cfg.replace(loop=cfg.loop.replace(mpc=cfg.loop.mpc.replace(lam_st=7.5)))
    stream = TelemetryStream()
    rec = Recorder(stream, RecorderConfig(), directory=tmp_path)
    sid = rec.start(label="w", config_toml=cfg.to_toml(redact=True))
    stream.publish(ch.SETPOINTS, Setpoints(0.0, 0.1, 1.0, 0.0))
    rec.stop()
    bare = recorded(tmp_path, "bare", "")
    runs = RunLibrary(tmp_path)
    try:
        runs.refresh()
        views = {v.id: v for v in runs.find("", "start", False)}
        assert dict(views[sid].weights) == {"lam_f": cfg.loop.mpc.lam_f, "lam_st": 7.5,
                                            "lam_a": cfg.loop.mpc.lam_a, "lam_d": cfg.loop.mpc.lam_d}
        assert "lam_st=7.5" in views[sid].weights_text()
        assert views[bare].weights == ()  # no configuration recorded: no weights, not zeros
    finally:
        runs.close()


def test_open_report_sends_the_runs_report_and_says_when_there_is_none(
        make_console: Callable[..., Console], two_runs: tuple[str, str], tmp_path: Path) -> None:
    a, b = two_runs
    (tmp_path / f"{a}.report.html").write_text("<html>report of a</html>")
    review = Review(make_console(console_config(**SETTINGS), serve=True))
    review.choose(b)
    review.press(review.runs.report_button)
    assert "no report file" in review.refused(f"{b}: no report")
    review.choose(a)
    review.press(review.runs.report_button)
    review.refused(f"report {a}.report.html sent")


def test_a_runs_start_is_shown_in_utc_whatever_the_servers_time_zone(monkeypatch: pytest.MonkeyPatch) -> None:
    import time
    from types import SimpleNamespace

    from ucat_console.ui.run_list import COLUMNS, run_cells

    row = SimpleNamespace(figures={}, config="sim-tuned", config_hash="", notes="", id="r1", status="ok",
                          start=1_765_000_000.0, duration=60.0, modes=("mpc",), manoeuvre="", tags=())
    view = SimpleNamespace(row=row, weights_text=lambda: "")
    monkeypatch.setenv("TZ", "Pacific/Auckland")  # UTC+13 in December
    time.tzset()
    try:
        cells = dict(zip((h for h, _ in COLUMNS), run_cells(view)))
    finally:
        monkeypatch.undo()
        time.tzset()
    assert cells["start (UTC)"] == "2025-12-06 05:46"  # 1,765,000,000 s after the epoch, in UTC
