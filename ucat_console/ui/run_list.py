"""The Review tab's runs: the run library's list with a search, a sort and a direction, and a
run's tags, notes and report (what :class:`~ucat_console.backend.review.session.ReviewSession`
does with the library, rendered; the page's playback panel holds it).

The search takes the library's query language (docs/library.md); the list shows each run's
start, duration, modes, configuration and MPC weights, manoeuvre, energy per metre with its
interval, tags and notes, and the Session chooser above the playback holds the runs found.
A refused query, sort or direction shows the library's error and nothing else changes (the
list stays the last one found). Tags and notes are written for the run chosen, through the
supervisor (the pilot, or a page that has given its name; checked there); "Open report"
sends the run's report file to the page that asked, with viser's ``send_file_download``.
"""

from __future__ import annotations

import math
import time
from typing import Any, Callable, Sequence

from ucat_console.backend.review.session import RunsAccess
from ucat_console.backend.sessions.sidecar import MAX_NOTES
from ucat_console.ui.markdown import esc

#: the sort choices the page offers (the supervisor checks any value sent)
SORT_CHOICES = ("start", "duration", "epm", "cot", "power", "speed", "speed_mae", "st_mae", "st_in",
                "config", "manoeuvre", "id", "markers", "tags")
#: the most runs the list shows (the chooser holds every run found)
MAX_SHOWN = 60
#: the longest notes shown in the list (characters)
NOTES_SHOWN = 80
QUERY_HINT = ("the library's query language: mode=mpc speed>0.15 tag:pool-3 date>=2026-12-01 "
              'notes~"weak fin" -tag:draft; a word matches notes, id, manoeuvre, configuration')


def runs_access(sup: Any, who: Any) -> RunsAccess:
    """The run library as page ``who`` (a client id, or the console's LOCAL) uses it: the
    supervisor's methods, the writes in ``who``'s name."""
    return RunsAccess(
        find=sup.find_runs, refresh=sup.refresh_runs,
        set_tags=lambda sid, changes: sup.set_run_tags(who, sid, changes),
        set_notes=lambda sid, notes: sup.set_run_notes(who, sid, notes),
        report=sup.run_report,
    )


def describe_run(sup: Any, session_id: str) -> str:
    """A run's modes and MPC weights, as the comparison names them (ValueError: not in the library)."""
    v = sup.run_view(session_id)
    return "; ".join(x for x in ("/".join(v.row.modes), v.weights_text()) if x)


def _num(v: float | None, fmt: str = ".1f") -> str:
    return "–" if v is None or not math.isfinite(v) else format(v, fmt)


def _when(start: float | None) -> str:
    if start is None or not math.isfinite(start):
        return "–"
    return time.strftime("%Y-%m-%d %H:%M", time.localtime(start))


def run_line(view: Any) -> str:
    """One run as a Markdown list item (every text escaped)."""
    r = view.row
    f = r.figures
    epm = "J/m –" if f.get("epm") is None else (
        f"{_num(f.get('epm'))} J/m [{_num(f.get('epm_lo'))}, {_num(f.get('epm_hi'))}]")
    config = r.config or (r.config_hash[:8] if r.config_hash else "–")
    weights = view.weights_text()
    notes = " ".join(r.notes.split())
    if len(notes) > NOTES_SHOWN:
        notes = notes[: NOTES_SHOWN - 1] + "…"
    parts = [
        f"**{esc(r.id)}**", esc(_when(r.start)), f"{_num(r.duration, '.0f')} s",
        esc("/".join(r.modes) or "–"), esc(config) + (f" ({esc(weights)})" if weights else ""),
        esc(r.manoeuvre or "–"), esc(epm),
    ]
    if r.status != "ok":
        parts.append(f"**{esc(r.status)}**")
    if r.tags:
        parts.append("tags " + esc(", ".join(r.tags)))
    if notes:
        parts.append("notes: " + esc(notes))
    return "- " + " · ".join(parts)


def runs_markdown(views: Sequence[Any], query: str) -> str:
    if not views:
        return "No run matches." if query.strip() else "No runs recorded yet."
    lines = [run_line(v) for v in views[:MAX_SHOWN]]
    if len(views) > MAX_SHOWN:
        lines.append(f"- … {len(views) - MAX_SHOWN} more (in the Session chooser; narrow the search)")
    head = f"{len(views)} run{'s' if len(views) != 1 else ''}" + (f" match {esc(query)}" if query.strip() else "")
    return head + ":\n\n" + "\n".join(lines)


class RunList:
    """The Review tab's runs (module docstring): built in the current container by the
    playback panel, which runs its commands (``job(what, fn, value)``: a callback handing
    ``fn(value())`` to the page's jobs; ``act(fn)``: run ``fn`` showing a refusal)."""

    def __init__(self, gui: Any, review: Any, *, chosen: Callable[[], str],
                 job: Callable[..., Callable[[Any], None]], show: Callable[[str], None],
                 listed: Callable[[tuple[str, ...]], None] = lambda ids: None,
                 allow: Callable[..., None] | None = None) -> None:
        """``chosen()``: the run the Session chooser names; ``listed(ids)``: the runs found
        (the chooser's options)."""
        self.review = review  # the ReviewSession
        self.chosen = chosen
        self.listed = listed
        self.show = show
        self.views: list[Any] = []
        self._filled_for: str | None = None  # the run whose notes the Notes input was given
        with gui.add_folder("Runs", order=0.5):
            self.search = gui.add_text("Search", "", hint=QUERY_HINT)
            self.sort = gui.add_dropdown("Sort by", SORT_CHOICES, initial_value="start",
                                         hint="epm: energy per metre; *_mae: tracking errors; st_in: strokes in the corridor")
            self.desc = gui.add_checkbox("Latest / largest first", True)
            self.table = gui.add_markdown("")
            self.tags = gui.add_text("Tags", "", hint="changes to the chosen run's tags: +pool-3 -draft "
                                                      "(letters, digits, _ . : -)")
            self.save_tags = gui.add_button("Save tags", hint="the pilot, or a page that has given its name")
            self.notes = gui.add_text("Notes", "", multiline=True, hint=f"the chosen run's notes, at most {MAX_NOTES} "
                                                                        "characters (the recording keeps its own)")
            self.save_notes = gui.add_button("Save notes", hint="the pilot, or a page that has given its name")
            self.report_button = gui.add_button("Open report", hint="the chosen run's report file, when it has one")
        self.search.on_update(job("Search", self.find, True, value=lambda: self.search.value))
        self.sort.on_update(job("Sort", lambda v: self.find(sort=v), True, value=lambda: self.sort.value))
        self.desc.on_update(job("Sort", lambda v: self.find(desc=v), True, value=lambda: self.desc.value))
        self.save_tags.on_click(job("Save tags", lambda v: self.write_tags(*v), False,
                                    value=lambda: (self.chosen(), self.tags.value)))
        self.save_notes.on_click(job("Save notes", lambda v: self.write_notes(*v), False,
                                     value=lambda: (self.chosen(), self.notes.value)))
        if allow is not None:
            for h in (self.sort, self.desc, self.save_tags, self.save_notes, self.report_button):
                allow(h, False)
            allow(self.search, False, 500)
            allow(self.tags, False, 500)
            allow(self.notes, False, MAX_NOTES * 4)  # bytes of UTF-8; the characters are checked on the server

    def handles(self) -> tuple[Any, ...]:
        return (self.search, self.sort, self.desc, self.tags, self.save_tags, self.notes, self.save_notes,
                self.report_button)

    def find(self, query: object = None, sort: object = None, desc: object = None, refresh: bool = False) -> list[Any]:
        """List the runs (None: the last accepted query, sort, direction); refused: shown, the
        list stays."""
        self.views = self.review.find_runs(query, sort, desc, refresh=refresh)
        self.table.content = runs_markdown(self.views, self.review.query[0])
        self.listed(self.ids())
        return self.views

    def ids(self) -> tuple[str, ...]:
        return tuple(v.id for v in self.views)

    def row(self, session_id: str) -> Any:
        return next((v.row for v in self.views if v.id == session_id), None)

    def chose(self, session_id: str) -> None:
        """The chooser names ``session_id``: its notes in the Notes input, when it names
        another run than before (a list shown again keeps what is being typed)."""
        if session_id == self._filled_for:
            return
        self._filled_for = session_id
        row = self.row(session_id)
        notes = row.notes if row is not None else ""
        if self.notes.value != notes:
            self.notes.value = notes

    def write_tags(self, session_id: object, text: object) -> tuple[str, ...]:
        tags = self.review.set_tags(session_id, text)
        self.tags.value = ""
        self.find()
        self.show(self.review.said)
        return tags

    def write_notes(self, session_id: object, notes: object) -> str:
        text = self.review.set_notes(session_id, notes)
        self.find()
        self.show(self.review.said)
        return text

    def send_report(self, session_id: object, send: Callable[[str, bytes], Any]) -> str:
        name, content = self.review.report(session_id)
        send(name, content)
        self.show(self.review.said)
        return name
