"""The Review tab's runs: the run library's list with a search, a sort and a direction, and a
run's tags, notes and report (what :class:`~ucat_console.backend.review.session.ReviewSession`
does with the library, rendered; the page's playback panel holds it).

The search takes the library's query language (docs/library.md); the table shows each run's
id, start (UTC), duration, modes, configuration and MPC weights, manoeuvre, energy per metre with
its interval, tags and notes, :data:`PAGE_ROWS` runs a page (More runs / Previous runs), and
the Session chooser below holds every run found (choose one there and Open it). viser's
Markdown element draws the table (a GitHub-style table); it has no clickable headers, so
the Sort by dropdown and the direction checkbox sort it, and the heading of the column
sorted by carries the direction's arrow. A refused query, sort or direction shows the
library's error and nothing else changes (the list stays the last one found). The Trends
folder below draws a figure of the runs found (:mod:`~ucat_console.ui.trend_panel`). Tags and notes are written for the run chosen, through the
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
from ucat_console.ui.trend_panel import TrendPanel

#: the sort choices the page offers (the supervisor checks any value sent)
SORT_CHOICES = ("start", "duration", "epm", "cot", "power", "speed", "speed_mae", "st_mae", "st_in",
                "config", "manoeuvre", "id", "markers", "tags")
#: the runs a page of the table shows (the chooser holds every run found)
PAGE_ROWS = 20
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
        report=sup.run_report, trend=sup.trend_runs,
    )


def describe_run(sup: Any, session_id: str) -> str:
    """A run's modes and MPC weights, as the comparison names them (ValueError: not in the library)."""
    v = sup.run_view(session_id)
    return "; ".join(x for x in ("/".join(v.row.modes), v.weights_text()) if x)


def _num(v: float | None, fmt: str = ".1f") -> str:
    return "–" if v is None or not math.isfinite(v) else format(v, fmt)


def _when(start: float | None) -> str:
    """A run's start in UTC, as the library's ``date`` queries and the reports give it (the
    robot's computer and the operator's laptop may not share a time zone)."""
    if start is None or not math.isfinite(start):
        return "–"
    return time.strftime("%Y-%m-%d %H:%M", time.gmtime(start))


#: the table's columns: (heading, the sort field it is sorted by, or "")
COLUMNS = (("run", "id"), ("start (UTC)", "start"), ("s", "duration"), ("mode", ""), ("config (weights)", "config"),
           ("manoeuvre", "manoeuvre"), ("J/m [lo, hi]", "epm"), ("tags", "tags"), ("notes", ""))


def _cell(text: str) -> str:
    """Text for one table cell: escaped, on one line ("–" when empty)."""
    return esc(" ".join(text.split())) or "–"


def run_cells(view: Any) -> list[str]:
    """One run's cells, in :data:`COLUMNS`' order (every text escaped)."""
    r = view.row
    f = r.figures
    epm = "–" if f.get("epm") is None else (
        f"{_num(f.get('epm'))} [{_num(f.get('epm_lo'))}, {_num(f.get('epm_hi'))}]")
    config = r.config or (r.config_hash[:8] if r.config_hash else "–")
    weights = view.weights_text()
    notes = " ".join(r.notes.split())
    if len(notes) > NOTES_SHOWN:
        notes = notes[: NOTES_SHOWN - 1] + "…"
    run = f"**{esc(r.id)}**" + (f" ({esc(r.status)})" if r.status != "ok" else "")
    return [run, _cell(_when(r.start)), _num(r.duration, ".0f"), _cell("/".join(r.modes)),
            _cell(config) + (f" ({esc(weights)})" if weights else ""), _cell(r.manoeuvre),
            esc(epm), _cell(", ".join(r.tags)), _cell(notes)]


def runs_markdown(views: Sequence[Any], query: str, page: int = 0, sort: str = "start", desc: bool = True) -> str:
    """The runs found as a Markdown table: one page of :data:`PAGE_ROWS` rows (``page`` from
    0), the column sorted by marked with its direction, a line saying which rows are shown."""
    if not views:
        return "No run matches." if query.strip() else "No runs recorded yet."
    pages = max(1, math.ceil(len(views) / PAGE_ROWS))
    page = min(max(0, page), pages - 1)
    first = page * PAGE_ROWS
    shown = views[first:first + PAGE_ROWS]
    arrow = " ▼" if desc else " ▲"
    heads = [h + (arrow if key == sort else "") for h, key in COLUMNS]
    head = f"{len(views)} run{'s' if len(views) != 1 else ''}" + (f" match {esc(query)}" if query.strip() else "")
    sorted_by = "" if any(key == sort for _, key in COLUMNS) else f"; sorted by {esc(sort)}{arrow}"
    where = (f"runs {first + 1}–{first + len(shown)} of {len(views)} (page {page + 1} of {pages}; "
             "More runs / Previous runs)" if pages > 1 else "")
    lines = [head + ":" + (f" {where}" if where else "") + sorted_by, "",
             "| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    lines += ["| " + " | ".join(run_cells(v)) + " |" for v in shown]
    return "\n".join(lines)


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
        self.on_found: Callable[[], None] | None = None  # called after each list found (the trend)
        self.views: list[Any] = []
        self.page = 0  # the table's page shown (from 0)
        self._filled_for: str | None = None  # the run whose notes the Notes input was given
        with gui.add_folder("Runs", order=0.5):
            self.search = gui.add_text("Search", "", hint=QUERY_HINT)
            self.sort = gui.add_dropdown("Sort by", SORT_CHOICES, initial_value="start",
                                         hint="epm: energy per metre; *_mae: tracking errors; st_in: strokes in the corridor")
            self.desc = gui.add_checkbox("Latest / largest first", True)
            self.table = gui.add_markdown("")
            self.prev_page = gui.add_button("Previous runs", disabled=True, hint="the page of the table before")
            self.next_page = gui.add_button("More runs", disabled=True, hint="the next page of the table")
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
        self.prev_page.on_click(job("Page", lambda v: self.turn(-1), False, value=lambda: None))
        self.next_page.on_click(job("Page", lambda v: self.turn(1), False, value=lambda: None))
        self.save_tags.on_click(job("Save tags", lambda v: self.write_tags(*v), False,
                                    value=lambda: (self.chosen(), self.tags.value)))
        self.save_notes.on_click(job("Save notes", lambda v: self.write_notes(*v), False,
                                     value=lambda: (self.chosen(), self.notes.value)))
        self.trend: TrendPanel | None = None
        if getattr(review.runs, "trend", None) is not None:
            self.trend = TrendPanel(gui, review, job=job, allow=allow)
            self.on_found = self.trend.found
        if allow is not None:
            for h in (self.sort, self.desc, self.save_tags, self.save_notes, self.report_button, self.prev_page,
                      self.next_page):
                allow(h, False)
            allow(self.search, False, 500)
            allow(self.tags, False, 500)
            allow(self.notes, False, MAX_NOTES * 4)  # bytes of UTF-8; the characters are checked on the server

    def handles(self) -> tuple[Any, ...]:
        return (self.search, self.sort, self.desc, self.prev_page, self.next_page, self.tags, self.save_tags,
                self.notes, self.save_notes, self.report_button, *(self.trend.handles() if self.trend else ()))

    def find(self, query: object = None, sort: object = None, desc: object = None, refresh: bool = False) -> list[Any]:
        """List the runs (None: the last accepted query, sort, direction); refused: shown, the
        list stays."""
        self.views = self.review.find_runs(query, sort, desc, refresh=refresh)
        if query is not None or sort is not None or desc is not None:
            self.page = 0  # another query or order: its first page
        self._draw()
        self.listed(self.ids())
        if self.on_found is not None:
            self.on_found()
        return self.views

    def pages(self) -> int:
        return max(1, math.ceil(len(self.views) / PAGE_ROWS))

    def turn(self, by: int) -> int:
        """Show the table's page ``by`` pages on (clamped to the pages there are); the page now."""
        self.page += by
        self._draw()
        return self.page

    def _draw(self) -> None:
        self.page = min(max(0, self.page), self.pages() - 1)
        q, s, d = self.review.query
        content = runs_markdown(self.views, q, self.page, s, d)
        if self.table.content != content:
            self.table.content = content
        self.prev_page.disabled = self.page == 0
        self.next_page.disabled = self.page >= self.pages() - 1

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
