"""A run's HTML report: made from a session recorded through the real recorder, parsed as
HTML and checked against what the session says when read on its own (markers, mode changes,
segments, the configuration's name); untrusted text escaped; a truncated session refused by
name with no file left; a session without figures said so; the CLI; the report written
after a recording stops (the recorder's stop listener), waited for, never slept for."""

from __future__ import annotations

import html
import time
from html.parser import HTMLParser
from pathlib import Path

import pytest
from session_helpers import record
from synthetic_run import run_items
from support import SHORT_LADDER

from ucat_console.backend.review.run_report import SUFFIX, ReportWriter, report_path, write_report
from ucat_console.backend.sessions import sidecar
from ucat_console.backend.sessions.reader import SessionParts
from ucat_console.backend.sessions.recorder import Recorder
from ucat_console.cli import main
from ucat_console.telemetry import channels as C
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import Status
from ucat_console.telemetry.stream import TelemetryStream

EVIL = '<script>alert("x")</script><img src=x onerror=alert(1)>'
TOML = ('robot = "sim"\n[loop]\nmode = "mpc"\n[loop.mpc]\nformulation = "paper"\n'
        '# a comment with <b>markup</b> & an ampersand\n')


class _Page(HTMLParser):
    """The tags and the text of a page (html.parser: what a browser would make of it)."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[str] = []
        self.attrs: list[tuple[str, str | None]] = []
        self.text: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        self.attrs += attrs

    def handle_data(self, data: str) -> None:
        self.text.append(data)

    @property
    def all_text(self) -> str:
        return "".join(self.text)


def _parse(path: Path) -> _Page:
    p = _Page()
    p.feed(path.read_text(encoding="utf-8"))
    p.close()
    return p


def _events() -> tuple[Event, ...]:
    seg = tuple(Event(4.0 + 3.0 * k, "manoeuvre", "segment", f"ladder #{k + 1} {label}", "info",
                      {"manoeuvre": "ladder", "index": k, "label": label, "t0": 1.0 + 3.0 * k, "t1": 4.0 + 3.0 * k})
                for k, label in enumerate(("slow", "fast")))
    return (
        Event(0.5, "operator", "marker", "fin 2 looks weak", "info"),
        Event(2.0, "operator", "marker", EVIL, "info"),
        Event(3.0, "loop", "mode", "controller mpc -> baseline", "info", {"from": "mpc", "to": "baseline"}),
        Event(3.5, "loop", "tuning", "pilot: mpc.lam_st 2 -> 3", "info"),
        Event(5.0, "failsafe", "depth_limit", "too deep", "error"),
        Event(5.5, "seek", "candidate", "candidate 1: lam_st=3", "info"),
        *seg,
    )


@pytest.fixture
def session(sessions: Path) -> str:
    items = [*run_items(8.0, events=_events()), (C.STATUS, Status(0.05, True, "mpc", "", (), 0, "sim"))]
    [path] = record(sessions, sorted(items, key=lambda it: it[1].t), label="pool", notes=f"notes {EVIL}",
                    config_toml=TOML, config_name="pool-tuned")
    return path.name.removesuffix("_001.mcap")


def test_report_holds_the_session_as_read_on_its_own(sessions: Path, session: str) -> None:
    sidecar.write(sessions, session, sidecar.Sidecar(tags=("pool-3",), operator="Kati"))
    report = write_report(session, None, sessions)
    assert report.path == report_path(session, sessions) == sessions / f"{session}{SUFFIX}"
    page = _parse(report.path)
    text = page.all_text
    with SessionParts(session, sessions) as s:  # the session read without the report's code
        events = s.events()
        notes = s.notes
        config = s.metadata["config"]["name"]
    markers = [e.message for e in events if e.code == "marker"]
    modes = [e.message for e in events if e.code == "mode"]
    segments = [e.data["label"] for e in events if e.code == "segment"]
    assert len(markers) == 2 and modes and len(segments) == 2
    for want in (session, config, notes, *markers, *modes, "pool-3", "Kati", "depth_limit",
                 "pilot: mpc.lam_st 2 -> 3", "candidate 1: lam_st=3"):
        assert want in text, want
    for label in segments:  # a Table V row per manoeuvre segment
        assert f"{label}" in text
    assert "# a comment with <b>markup</b> & an ampersand" in text  # the configuration, as text
    assert {"img", "table", "pre"} <= set(page.tags)
    assert sum(1 for t in page.tags if t == "img") == 4  # timeline, tracking, power, Strouhal
    assert all(v.startswith("data:image/png;base64,") for k, v in page.attrs if k == "src" and v)
    assert not any(k == "href" for k, _ in page.attrs)  # nothing fetched from elsewhere


def test_untrusted_text_is_escaped(sessions: Path, session: str) -> None:
    path = write_report(session, None, sessions).path
    raw = path.read_text(encoding="utf-8")
    page = _parse(path)
    assert "script" not in page.tags
    assert not any(k.startswith("on") for k, _ in page.attrs)
    assert EVIL not in raw and html.escape(EVIL) in raw
    assert EVIL in page.all_text  # shown as the text it is


def test_a_truncated_session_is_refused_by_name_and_leaves_no_file(sessions: Path, session: str,
                                                                   tmp_path: Path) -> None:
    part = sessions / f"{session}_001.mcap"
    data = part.read_bytes()
    part.write_bytes(data[: len(data) // 2])
    out = tmp_path / "r.html"
    with pytest.raises(ValueError, match=part.name):
        write_report(session, out, sessions)
    assert not out.exists()
    assert not list(tmp_path.glob("*.tmp")) and not list(sessions.glob("*" + SUFFIX)) \
        and not list(sessions.glob(".*.tmp"))


def test_a_session_never_driven_says_what_is_missing(sessions: Path) -> None:
    [path] = record(sessions, [(C.STATUS, Status(0.0, False, "mpc", "", (), 0, "sim")),
                               (C.STATUS, Status(1.0, False, "mpc", "", (), 0, "sim"))], label="idle")
    report = write_report(path, None, sessions)
    text = _parse(report.path).all_text
    assert any("no power messages" in m for m in report.missing)
    assert any("the configuration" in m for m in report.missing)
    assert "Missing" in text and "no power messages" in text


def test_cli_writes_the_report_beside_the_session_or_where_told(sessions: Path, session: str, tmp_path: Path,
                                                                capsys) -> None:
    assert main(["sessions", "report", session, "--dir", str(sessions)]) == 0
    assert (sessions / f"{session}{SUFFIX}").is_file()
    out = tmp_path / "elsewhere.html"
    assert main(["sessions", "report", str(sessions / f"{session}_001.mcap"), "--out", str(out)]) == 0
    assert "fin 2 looks weak" in _parse(out).all_text
    assert str(out) in capsys.readouterr().out
    assert main(["sessions", "report", "no-such-session", "--dir", str(sessions)]) != 0
    assert "no-such-session" in capsys.readouterr().err


def _wait_for(cond, what: str, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"{what}: not within {timeout:g} s")
        time.sleep(0.05)


def test_a_stopped_recording_gets_its_report(sessions: Path) -> None:
    done: list[tuple[object, str]] = []
    writer = ReportWriter(on_done=lambda r, e: done.append((r, e)))
    stream = TelemetryStream()
    rec = Recorder(stream, directory=sessions, epoch_offset=1.7e9)
    rec.add_stop_listener(writer.submit)
    sid = rec.start(label="hook", notes="the hook's run", config_toml=TOML)
    for channel, msg in run_items(4.0, events=(Event(1.0, "operator", "marker", "hooked", "info"),)):
        stream.publish(channel, msg)
    rec.stop()
    path = report_path(sid, sessions)
    _wait_for(lambda: bool(done), "the report")
    assert done[0][1] == "" and path.is_file()
    assert "hooked" in _parse(path).all_text


def test_a_failed_report_is_said_once_and_never_raised(sessions: Path, caplog) -> None:
    done: list[tuple[object, str]] = []
    writer = ReportWriter(on_done=lambda r, e: done.append((r, e)))
    writer.submit("gone", [sessions / "gone_001.mcap"])  # no such file
    _wait_for(lambda: bool(done), "the failure")
    assert done[0][0] is None and "gone" in done[0][1]
    assert writer.join(10.0)
    assert sum("gone" in r.getMessage() for r in caplog.records) == 1


def test_a_discarded_recording_gets_no_report(sessions: Path) -> None:
    called: list[str] = []
    stream = TelemetryStream()
    rec = Recorder(stream, directory=sessions, epoch_offset=1.7e9)
    rec.add_stop_listener(lambda sid, paths: called.append(sid))
    rec.start(label="dropped")
    rec.discard()
    sid = rec.start(label="kept")
    rec.stop()
    assert called == [sid]




@pytest.mark.slow
def test_the_simulated_console_writes_the_report_of_its_recording(tmp_path: Path, monkeypatch, capsys) -> None:
    from ucat_console.backend.sessions import files

    monkeypatch.setenv(files.SESSIONS_ENV, str(tmp_path))
    script = tmp_path / "short.toml"
    script.write_text(SHORT_LADDER)
    assert main(["run", "--config", "sim-tuned", "--headless", "--fast", "--manoeuvre", str(script)]) == 0
    capsys.readouterr()
    [part] = tmp_path.glob("*_001.mcap")
    sid = part.name.removesuffix("_001.mcap")
    path = report_path(sid, tmp_path)
    _wait_for(path.is_file, "the report")  # written as the recording stopped
    text = _parse(path).all_text
    with SessionParts(sid, tmp_path) as s:
        segments = [e.data["label"] for e in s.events() if e.code == "segment"]
        name = s.metadata["config"]["name"]
    assert segments == ["slow", "fast"] and name == "sim-tuned"
    for want in (sid, name, "#1 slow", "#2 fast", "baseline"):
        assert want in text, want
