"""The console's run library: the sessions folder's :class:`~ucat_console.backend.sessions.library.Library`
as the pages find, tag and annotate runs through the supervisor, every value a page sends checked here.

:class:`RunLibrary` holds one ``Library`` for the console (opened at its first use, with the
names of the shipped configurations, ``config.known_configs``, which the supervisor hands it) and answers the supervisor's
``find_runs``, ``refresh_runs``, ``set_run_tags``, ``set_run_notes``, ``run_report`` and
``trend_runs`` (a figure of the runs a query finds, by day or by a recorded MPC weight: the
choices of :mod:`~ucat_console.backend.review.trend`).
Values come from a page as it sent them: each is checked for its type, its length and its
characters before anything is read or written (:func:`check_query`, :func:`check_tag_changes`,
:func:`check_notes`); a refusal is a ValueError naming the value, and nothing is written then.
Who may write, and the journal of what was written, are the supervisor's.

Each row a page shows is a :class:`RunView`: the library's row and the MPC weights of the
configuration it recorded (from the library's copy of that configuration's text).
"""

from __future__ import annotations

import logging
import threading
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping

from ucat_console.backend.review import trend as trends
from ucat_console.backend.sessions import sidecar
from ucat_console.backend.sessions.library import Library, RefreshReport, Row, TrendPoint
from ucat_console.backend.sessions.library_query import FIELDS, MANY
from ucat_console.backend.sessions.limits import MemoryBudget
from ucat_console.backend.sessions.replay import WEIGHT_NAMES

log = logging.getLogger(__name__)

#: the longest query a page may send (characters)
MAX_QUERY = 500
#: the most tag changes in one write
MAX_TAG_CHANGES = 16
#: the fields a page may sort by (every field of one value)
SORTS = tuple(k for k, f in FIELDS.items() if f.kind != MANY)
#: the longest session id a page may name
MAX_ID = 200


@dataclass(frozen=True)
class RunView:
    """One run as a page lists it: the library's row and its recorded MPC weights (those
    its configuration names; empty when it recorded none)."""

    row: Row
    weights: tuple[tuple[str, float], ...]

    @property
    def id(self) -> str:
        return self.row.id

    def weights_text(self) -> str:
        """``lam_f=1.5 lam_st=2`` ("" when none was recorded)."""
        return " ".join(f"{k}={v:g}" for k, v in self.weights)


def check_query(query: object, sort: object, desc: object) -> tuple[str, str, bool]:
    """A page's query, sort field and direction, or ValueError naming the bad one (the query's
    own terms are checked by the library's parser)."""
    if not isinstance(query, str) or len(query) > MAX_QUERY:
        raise ValueError(f"query: expected text of at most {MAX_QUERY} characters")
    if not query.isprintable():
        raise ValueError("query: only printable characters (no line breaks or control characters)")
    if not isinstance(sort, str) or sort not in SORTS:
        raise ValueError(f"sort: {str(sort)[:40]!r} is not one of {', '.join(SORTS)}")
    if not isinstance(desc, bool):
        raise ValueError(f"direction: expected true or false, got {type(desc).__name__}")
    return query, sort, desc


def check_session_id(session_id: object) -> str:
    if (not isinstance(session_id, str) or not session_id or len(session_id) > MAX_ID
            or not session_id.isprintable() or "/" in session_id or "\\" in session_id
            or session_id in (".", "..")):
        raise ValueError(f"session: {str(session_id)[:80]!r} is not a session id")
    return session_id


def check_tag_changes(changes: object) -> list[str]:
    """``["+pool-3", "-draft"]`` checked: a list of at most :data:`MAX_TAG_CHANGES` changes,
    each ``+TAG``, ``-TAG`` or ``TAG`` with TAG as :func:`~.sidecar.check_tag` allows."""
    if not isinstance(changes, (list, tuple)) or not changes:
        raise ValueError("tags: expected changes such as +pool-3 -draft")
    if len(changes) > MAX_TAG_CHANGES:
        raise ValueError(f"tags: at most {MAX_TAG_CHANGES} changes at once, got {len(changes)}")
    out = []
    for c in changes:
        if not isinstance(c, str) or not c:
            raise ValueError(f"tag change {str(c)[:80]!r}: expected +TAG or -TAG")
        sidecar.check_tag(c[1:] if c[0] in "+-" else c)
        out.append(c)
    return out


def check_notes(notes: object) -> str:
    """Notes of at most :data:`~.sidecar.MAX_NOTES` characters, printable but for line breaks and tabs."""
    text = sidecar.check_text("notes", notes)
    if not text.replace("\n", "").replace("\t", "").isprintable():
        raise ValueError("notes: only printable characters, line breaks and tabs")
    return text


def report_path(session_id: str, directory: Path) -> Path:
    """Where a session's report file is (``backend.review.run_report`` when the console has
    it, else ``<sessions folder>/<session id>.report.html``)."""
    try:
        from ucat_console.backend.review import run_report  # type: ignore[attr-defined]
    except ImportError:
        return directory / f"{session_id}.report.html"
    return Path(run_report.report_path(session_id, directory))


class RunLibrary:
    """The console's run library (module docstring); thread-safe. ``names()``: the
    configurations' names by their hash (called once, at the first use)."""

    def __init__(self, directory: Path, budget: MemoryBudget | None = None,
                 names: Callable[[], Mapping[str, str]] = dict) -> None:
        self.directory = Path(directory)
        self.budget = budget
        self._names = names
        self._lock = threading.Lock()
        self._lib: Library | None = None
        self._weights: dict[str, tuple[tuple[str, float], ...]] = {}

    @property
    def library(self) -> Library:
        with self._lock:
            if self._lib is None:
                try:
                    names = dict(self._names())
                except Exception:  # naming is a convenience: the runs are listed without it
                    log.exception("the shipped configurations' names were not read")
                    names = {}
                self._lib = Library(self.directory, known_configs=names, budget=self.budget)
            return self._lib

    def close(self) -> None:
        with self._lock:
            lib, self._lib = self._lib, None
        if lib is not None:
            lib.close()

    def refresh(self) -> RefreshReport:
        return self.library.refresh()

    def find(self, query: object = "", sort: object = "start", desc: object = False) -> list[RunView]:
        q, s, d = check_query(query, sort, desc)
        return [self.view(r) for r in self.library.find(q, s, d)]

    def get(self, session_id: object) -> Row:
        return self.library.get(check_session_id(session_id))

    def view(self, row: Row) -> RunView:
        return RunView(row, self._weights_of(row.config_hash))

    def _weights_of(self, digest: str) -> tuple[tuple[str, float], ...]:
        if not digest:
            return ()
        got = self._weights.get(digest)
        if got is None:
            got = ()
            text = self.library.config_text(digest)
            try:
                doc: Any = tomllib.loads(text) if text else {}
            except tomllib.TOMLDecodeError:
                doc = {}
            loop = doc.get("loop") if isinstance(doc, dict) else None
            mpc = loop.get("mpc") if isinstance(loop, dict) and "mpc" in loop else doc.get("mpc") if isinstance(doc, dict) else None
            if isinstance(mpc, dict):
                got = tuple((k, float(mpc[k])) for k in WEIGHT_NAMES
                            if isinstance(mpc.get(k), (int, float)) and not isinstance(mpc.get(k), bool))
            self._weights[digest] = got
        return got

    def set_tags(self, session_id: object, changes: object) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(the tags before, the tags now) of a session after ``changes`` (checked first)."""
        sid, checked = check_session_id(session_id), check_tag_changes(changes)
        lib = self.library
        old = lib.get(sid).tags
        return old, lib.set_tags(sid, checked)

    def set_notes(self, session_id: object, notes: object) -> tuple[str, Row]:
        """(the notes before, the row now) of a session with ``notes`` (checked first)."""
        sid, text = check_session_id(session_id), check_notes(notes)
        lib = self.library
        old = lib.get(sid).notes
        return old, lib.set_notes(sid, text)

    def trend(self, query: object, figure: object, by: object) -> list[TrendPoint]:
        """``figure`` of the runs ``query`` finds against ``by`` (each checked first: one of
        the trend's choices; ValueError naming the one refused)."""
        q, _, _ = check_query(query, "start", False)
        name, axis = trends.check_choice(figure, by)
        return self.library.trend(name, axis, q)

    def report(self, session_id: object) -> Path | None:
        """The session's report file when there is one (None: none)."""
        p = report_path(check_session_id(session_id), self.directory)
        return p if p.is_file() and not p.is_symlink() else None
