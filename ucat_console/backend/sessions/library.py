"""The run library: an SQLite index of every session in the sessions folder, and its API.

:class:`Library` is what the shell (``ucat-console sessions find|tag|note|trend``) and the
page call: :meth:`~Library.refresh`, :meth:`~Library.find` (a query of
:mod:`~.library_query`, sorted), :meth:`~Library.set_tags`, :meth:`~Library.set_notes`,
:meth:`~Library.trend`. Each session's facts and figures are read by
:func:`~.library_read.read_facts`.

The database is ``.library.sqlite3`` inside the sessions folder (beside the files it
describes, so a folder copied elsewhere takes its index along; one in the user's cache
folder, named by the folder's path, when the sessions folder cannot be written). It is a
cache, never trusted over the files:

* a session is keyed by its id with each part file's name, size and modification time (and
  those of its sidecars, ``<id>.meta.json`` and ``<id>.markers.json``); :meth:`refresh`
  lists the folder (one directory scan, no file opened), re-reads the sessions whose files
  are new or changed (their sidecars alone when only those changed), and drops the sessions
  whose files are gone. With nothing changed it opens no file and writes nothing;
* a database that is missing, corrupt, or of another :data:`SCHEMA_VERSION` (the version
  counts the figures' definitions too) is deleted and built again from the files.

A repair's kept original (``*.orig.mcap``) is not a run of its own and is not indexed;
symbolic links are never read (as the listing). Tags, notes and the operator's name given
after recording live in the session's sidecar (:mod:`~.sidecar`) and in the index.
"""

from __future__ import annotations

import json
import logging
import math
import os
import sqlite3
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping

import platformdirs

from ucat_console.backend.sessions import files, sidecar
from ucat_console.backend.sessions.index import listed_as
from ucat_console.backend.sessions.library_query import FIELDS, QueryError, field, order_by, parse
from ucat_console.backend.sessions.library_read import FIGURE_COLUMNS, Facts, PartStat, read_facts
from ucat_console.backend.sessions.limits import MemoryBudget
from ucat_console.backend.sessions.markers import MarkerStore

log = logging.getLogger(__name__)

#: the database's schema and the figures' definitions; another version is rebuilt
SCHEMA_VERSION = 1
DB_NAME = ".library.sqlite3"

_FIG_COLS = [c + s for c, _, iv in FIGURE_COLUMNS for s in (("", "_lo", "_hi") if iv else ("",))]
#: the sessions table's columns after its key (all but the keys are facts or sidecar values)
_COLS = [
    "files_sig", "side_sig", "status", "error", "side_error", "start", "date", "duration", "size", "parts",
    "robot", "plant", "config", "recorded_config", "config_hash", "formulation", "mode", "manoeuvre",
    "segments", "segment_labels", "operator", "recorded_operator", "notes", "recorded_notes", "tags", "ntags",
    "recorded_markers", "review_markers", "markers", "failsafes", "failsafe_names", *_FIG_COLS,
    "figures_note", "driven_t0", "driven_t1",
]
_SCHEMA = f"""
CREATE TABLE sessions (id TEXT PRIMARY KEY, {", ".join(_COLS)});
CREATE TABLE parts (name TEXT PRIMARY KEY, id TEXT NOT NULL, size INTEGER, mtime_ns INTEGER);
CREATE TABLE vals (id TEXT NOT NULL, field TEXT NOT NULL, value TEXT NOT NULL);
CREATE INDEX vals_id ON vals (id);
CREATE INDEX vals_value ON vals (field, value COLLATE NOCASE);
CREATE INDEX parts_id ON parts (id);
CREATE TABLE configs (hash TEXT PRIMARY KEY, toml TEXT NOT NULL);
CREATE TABLE state (key TEXT PRIMARY KEY, value TEXT NOT NULL);
PRAGMA user_version = {SCHEMA_VERSION};
"""
#: the fields of several values, kept in ``vals`` and as a comma-joined column
_MANY_COLUMNS = {"mode": "mode", "tag": "tags", "failsafe": "failsafe_names", "segment": "segment_labels"}


@dataclass(frozen=True)
class Row:
    """One session of the library (figures None where there are none)."""

    id: str
    status: str
    error: str
    start: float | None
    date: str
    duration: float | None
    size: int
    parts: int
    robot: str
    plant: str
    config: str
    config_hash: str
    formulation: str
    modes: tuple[str, ...]
    manoeuvre: str
    segments: tuple[str, ...]
    operator: str
    notes: str
    tags: tuple[str, ...]
    markers: int
    failsafes: tuple[str, ...]
    figures: dict[str, float | None]
    figures_note: str
    side_error: str

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class RefreshReport:
    added: int
    updated: int  # files changed: re-read whole
    sidecars: int  # only the sidecars changed: re-read them
    removed: int
    unchanged: int
    rebuilt: str  # why the database was built again ("" when it was not)
    seconds: float


@dataclass(frozen=True)
class TrendPoint:
    """One session's value of a trend's figure, in its group; ``lo``/``hi``: the figure's
    interval where the library has one (energy per metre, cost of transport), else None."""

    session_id: str
    start: float | None
    group: str
    value: float
    lo: float | None = None
    hi: float | None = None


def _sig(stats: Iterable[PartStat]) -> str:
    return "|".join(f"{s.name}:{s.size}:{s.mtime_ns}" for s in stats)


def _join(values: Iterable[str]) -> str:
    return ",".join(values)


def _split(text: str | None) -> tuple[str, ...]:
    return tuple(v for v in (text or "").split(",") if v)


def _day(start: float | None) -> str | None:
    if start is None or not math.isfinite(start):
        return None
    try:
        return time.strftime("%Y-%m-%d", time.gmtime(start))
    except (OverflowError, ValueError, OSError):
        return None


def _scan(root: Path) -> tuple[dict[str, list[PartStat]], dict[str, list[PartStat]]]:
    """(session -> its part files in part order, session -> its sidecars) from one scan."""
    parts: dict[str, list[tuple[int, PartStat]]] = {}
    sides: dict[str, list[PartStat]] = {}
    with os.scandir(root) as it:
        for e in it:
            name = e.name
            if not name.isprintable() or e.is_symlink():
                continue
            is_part = name.endswith(files.SUFFIX) and not name.endswith(files.ORIGINAL_SUFFIX)
            side_of = (name.removesuffix(sidecar.SUFFIX) if name.endswith(sidecar.SUFFIX)
                       else name.removesuffix(files.MARKERS_SUFFIX) if name.endswith(files.MARKERS_SUFFIX) else None)
            if not is_part and side_of is None:
                continue
            try:
                if not e.is_file(follow_symlinks=False):
                    continue
                st = e.stat(follow_symlinks=False)
            except OSError:
                continue
            ps = PartStat(name, st.st_size, st.st_mtime_ns)
            if is_part:
                sid, part = listed_as(Path(name))
                parts.setdefault(sid, []).append((part, ps))
            else:
                sides.setdefault(side_of, []).append(ps)
    return ({sid: [p for _, p in sorted(ps, key=lambda x: (x[0], x[1].name))] for sid, ps in parts.items()},
            {sid: sorted(ps, key=lambda p: p.name) for sid, ps in sides.items()})


def default_db_path(root: Path) -> Path:
    """The database of the sessions folder ``root`` (module docstring)."""
    if os.access(root, os.W_OK):
        return root / DB_NAME
    import hashlib

    digest = hashlib.sha256(str(root).encode()).hexdigest()[:16]
    return platformdirs.user_cache_path("ucat-console") / "library" / f"{digest}.sqlite3"


class Library:
    """The run library of one sessions folder (module docstring). ``known_configs``: the
    names of configurations by the sha256 of their TOML text (the shipped ones', from the
    command line), naming a session's configuration when its recording names none;
    ``db``: the database file (default: :func:`default_db_path`). Safe to share between
    threads (one connection, one lock)."""

    def __init__(self, directory: str | Path | None = None, *, known_configs: Mapping[str, str] | None = None,
                 db: str | Path | None = None, budget: MemoryBudget | None = None) -> None:
        self.directory = files.sessions_dir(directory)
        self.known_configs = dict(known_configs or {})
        self.budget = budget if budget is not None else MemoryBudget()
        self.db_path = Path(db) if db is not None else default_db_path(self.directory)
        self._lock = threading.RLock()
        self._conn: sqlite3.Connection | None = None
        self.rebuilt = ""  # why the database was last built again ("" when it was not)

    # ------------------------------------------------------------------ the database
    def _connect(self) -> sqlite3.Connection:
        if self._conn is not None:
            return self._conn
        self.db_path.parent.mkdir(parents=True, exist_ok=True)
        why = ""
        if not self.db_path.exists():
            why = "no database"
        else:
            try:
                conn = sqlite3.connect(self.db_path, timeout=10.0, check_same_thread=False)
                version = conn.execute("PRAGMA user_version").fetchone()[0]
                if version != SCHEMA_VERSION:
                    why = f"schema version {version}, not {SCHEMA_VERSION}"
                else:
                    conn.execute("SELECT count(*) FROM sessions").fetchone()
                    if conn.execute("PRAGMA quick_check").fetchone()[0] != "ok":
                        why = "damaged (quick_check)"
                if not why:
                    self._conn = conn
                    return conn
                conn.close()
            except sqlite3.DatabaseError as e:
                why = f"unreadable ({e})"
        return self._create(why)

    def _create(self, why: str) -> sqlite3.Connection:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        for suffix in ("", "-journal", "-wal", "-shm"):
            Path(str(self.db_path) + suffix).unlink(missing_ok=True)
        log.debug("run library %s: built from the files (%s)", self.db_path, why)
        conn = sqlite3.connect(self.db_path, timeout=10.0, check_same_thread=False)
        conn.executescript(_SCHEMA)
        self._conn = conn
        self.rebuilt = why
        return conn

    def close(self) -> None:
        with self._lock:
            if self._conn is not None:
                self._conn.close()
                self._conn = None

    def __enter__(self) -> Library:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ------------------------------------------------------------------ refresh
    def refresh(self) -> RefreshReport:
        """Bring the index up to the files (module docstring); what it did."""
        with self._lock:
            try:
                return self._refresh()
            except sqlite3.DatabaseError as e:  # damaged under us: once more from the files
                self._create(f"unreadable ({e})")
                return self._refresh()

    def _refresh(self) -> RefreshReport:
        t0 = time.perf_counter()
        self.rebuilt = ""
        conn = self._connect()
        rebuilt = self.rebuilt
        if not self.directory.is_dir():
            found_parts: dict[str, list[PartStat]] = {}
            found_sides: dict[str, list[PartStat]] = {}
        else:
            found_parts, found_sides = _scan(self.directory)
        have = {sid: (fs, ss) for sid, fs, ss in conn.execute("SELECT id, files_sig, side_sig FROM sessions")}
        added = updated = sides = unchanged = 0
        gone = [sid for sid in have if sid not in found_parts]
        work: list[tuple[str, str, str, bool]] = []  # id, files sig, side sig, whole
        for sid, stats in found_parts.items():
            fsig, ssig = _sig(stats), _sig(found_sides.get(sid, []))
            old = have.get(sid)
            if old is None or old[0] != fsig:
                work.append((sid, fsig, ssig, True))
                added += old is None
                updated += old is not None
            elif old[1] != ssig:
                work.append((sid, fsig, ssig, False))
                sides += 1
            else:
                unchanged += 1
        names_changed = json.dumps(sorted(self.known_configs.items())) != self._state(conn, "known_configs")
        if gone or work or names_changed:
            with conn:
                for sid in gone:
                    self._delete(conn, sid)
                for sid, fsig, ssig, whole in work:
                    if whole:
                        paths = [self.directory / p.name for p in found_parts[sid]]
                        facts = read_facts(sid, paths, self.directory, budget=self.budget)
                        self.store(facts, found_parts[sid], fsig, conn=conn)
                    self._store_side(conn, sid, ssig)
                if names_changed or work:
                    self._name_configs(conn)
        return RefreshReport(added, updated, sides, len(gone), unchanged, rebuilt, time.perf_counter() - t0)

    @staticmethod
    def _state(conn: sqlite3.Connection, key: str) -> str:
        row = conn.execute("SELECT value FROM state WHERE key = ?", (key,)).fetchone()
        return row[0] if row else ""

    def _name_configs(self, conn: sqlite3.Connection) -> None:
        conn.execute("UPDATE sessions SET config = recorded_config")
        for digest, name in self.known_configs.items():
            conn.execute("UPDATE sessions SET config = ? WHERE config_hash = ? AND recorded_config = ''",
                         (name, digest))
        conn.execute("INSERT OR REPLACE INTO state VALUES ('known_configs', ?)",
                     (json.dumps(sorted(self.known_configs.items())),))

    @staticmethod
    def _delete(conn: sqlite3.Connection, sid: str) -> None:
        for table in ("sessions", "parts", "vals"):
            conn.execute(f"DELETE FROM {table} WHERE id = ?", (sid,))

    def _set_many(self, conn: sqlite3.Connection, sid: str, name: str, values: Iterable[str]) -> None:
        conn.execute("DELETE FROM vals WHERE id = ? AND field = ?", (sid, name))
        conn.executemany("INSERT INTO vals VALUES (?, ?, ?)", [(sid, name, v) for v in dict.fromkeys(values)])

    def store(self, facts: Facts, stats: list[PartStat], files_sig: str | None = None, *,
              conn: sqlite3.Connection | None = None) -> None:
        """Put one session's facts into the index (its sidecar values are set by the next
        :meth:`refresh`); ``files_sig``: the signature of ``stats`` (default: made here).
        Used by refresh, and by the benchmark to fill an index without reading files."""
        own = conn is None
        with self._lock:
            c = conn if conn is not None else self._connect()
            values: dict[str, Any] = {
                "files_sig": files_sig if files_sig is not None else _sig(stats), "side_sig": None,
                "status": facts.status, "error": facts.error, "side_error": "", "start": facts.start,
                "date": _day(facts.start), "duration": facts.duration, "size": facts.size, "parts": facts.parts,
                "robot": facts.robot, "plant": facts.plant, "config": facts.config,
                "recorded_config": facts.config,
                "config_hash": facts.config_hash, "formulation": facts.formulation, "mode": _join(facts.modes),
                "manoeuvre": facts.manoeuvre, "segments": len(facts.segments),
                "segment_labels": _join(facts.segments), "operator": facts.operator,
                "recorded_operator": facts.operator, "notes": facts.notes, "recorded_notes": facts.notes,
                "tags": "", "ntags": 0, "recorded_markers": facts.markers, "review_markers": 0,
                "markers": facts.markers, "failsafes": len(facts.failsafes),
                "failsafe_names": _join(facts.failsafes),
                **{k: facts.figures.get(k) for k in _FIG_COLS}, "figures_note": facts.figures_note,
                "driven_t0": facts.driven[0] if facts.driven else None,
                "driven_t1": facts.driven[1] if facts.driven else None,
            }
            try:
                self._delete(c, facts.session_id)
                c.execute(f"INSERT INTO sessions (id, {', '.join(_COLS)}) VALUES ({', '.join('?' * (len(_COLS) + 1))})",
                          (facts.session_id, *(values[k] for k in _COLS)))
                c.executemany("INSERT OR REPLACE INTO parts VALUES (?, ?, ?, ?)",
                              [(s.name, facts.session_id, s.size, s.mtime_ns) for s in stats])
                for name, values_of in (("mode", facts.modes), ("failsafe", facts.failsafes),
                                        ("segment", facts.segments)):
                    self._set_many(c, facts.session_id, name, values_of)
                if facts.config_toml:
                    c.execute("INSERT OR IGNORE INTO configs VALUES (?, ?)", (facts.config_hash, facts.config_toml))
                if own:
                    c.commit()
            except BaseException:
                if own:
                    c.rollback()
                raise

    def _store_side(self, conn: sqlite3.Connection, sid: str, side_sig: str) -> None:
        """Read the session's sidecars (tags, notes, operator; review markers) into its row."""
        errors = []
        try:
            side = sidecar.read(self.directory, sid)
        except ValueError as e:
            side, errors = sidecar.Sidecar(), [str(e)]
        try:
            review = len(MarkerStore(self.directory, sid).markers)
        except ValueError as e:
            review, errors = 0, [*errors, str(e)]
        conn.execute(
            "UPDATE sessions SET side_sig = ?, side_error = ?, tags = ?, ntags = ?, review_markers = ?, "
            "markers = recorded_markers + ?, notes = CASE WHEN ? IS NULL THEN recorded_notes ELSE ? END, "
            "operator = CASE WHEN ? IS NULL THEN recorded_operator ELSE ? END WHERE id = ?",
            (side_sig, "; ".join(errors), _join(side.tags), len(side.tags), review, review, side.notes,
             side.notes, side.operator, side.operator, sid))
        self._set_many(conn, sid, "tag", side.tags)

    # ------------------------------------------------------------------ queries
    def find(self, query: str = "", sort: str | None = None, desc: bool = False,
             limit: int | None = None) -> list[Row]:
        """The sessions matching ``query`` (:mod:`~.library_query`; "" for all), sorted by
        ``sort`` (default: start); QueryError (a ValueError) naming a bad term or field. Reads
        the index as it is (call :meth:`refresh` first to see the files' changes)."""
        q = parse(query)
        sql = f"SELECT * FROM sessions s WHERE {q.where} ORDER BY {order_by(sort, desc)}"
        params: tuple[object, ...] = q.params
        if limit is not None:
            sql += " LIMIT ?"
            params = (*params, int(limit))
        with self._lock:
            conn = self._connect()
            conn.row_factory = sqlite3.Row
            try:
                rows = conn.execute(sql, params).fetchall()
            finally:
                conn.row_factory = None
        return [self._row(r) for r in rows]

    @staticmethod
    def _row(r: sqlite3.Row) -> Row:
        return Row(
            id=r["id"], status=r["status"], error=r["error"] or "", start=r["start"], date=r["date"] or "",
            duration=r["duration"], size=r["size"], parts=r["parts"], robot=r["robot"], plant=r["plant"],
            config=r["config"], config_hash=r["config_hash"], formulation=r["formulation"],
            modes=_split(r["mode"]), manoeuvre=r["manoeuvre"], segments=_split(r["segment_labels"]),
            operator=r["operator"] or "", notes=r["notes"] or "", tags=_split(r["tags"]), markers=r["markers"],
            failsafes=_split(r["failsafe_names"]), figures={k: r[k] for k in _FIG_COLS},
            figures_note=r["figures_note"] or "", side_error=r["side_error"] or "",
        )

    def get(self, session_id: str) -> Row:
        """One session's row (ValueError when the index has none: refresh first)."""
        with self._lock:
            conn = self._connect()
            conn.row_factory = sqlite3.Row
            try:
                r = conn.execute("SELECT * FROM sessions s WHERE id = ?", (session_id,)).fetchone()
            finally:
                conn.row_factory = None
        if r is None:
            raise ValueError(f"session {session_id!r}: not in the library of {self.directory}")
        return self._row(r)

    def config_text(self, config_hash: str) -> str:
        """The recorded configuration's TOML text of that hash ("" when the index has none)."""
        with self._lock:
            row = self._connect().execute("SELECT toml FROM configs WHERE hash = ?", (config_hash,)).fetchone()
        return row[0] if row else ""

    # ------------------------------------------------------------------ tags and notes
    def _known(self, session_id: str) -> None:
        self.refresh()
        self.get(session_id)

    def set_tags(self, session_id: str, changes: list[str]) -> tuple[str, ...]:
        """Add (``+tag``) and remove (``-tag``) tags of a session: written to its sidecar, then
        the index; the tags now."""
        with self._lock:
            self._known(session_id)
            side = sidecar.read(self.directory, session_id)
            tags = sidecar.edit_tags(side.tags, changes)
            sidecar.write(self.directory, session_id, sidecar.Sidecar(tags, side.notes, side.operator))
            self.refresh()
            return tags

    def set_notes(self, session_id: str, notes: str | None = None, operator: str | None = None) -> Row:
        """Replace the notes (and/or the operator's name) of a session in its sidecar (the
        recording's own stay in the file; None: leave as it is), then the index; its row."""
        with self._lock:
            self._known(session_id)
            side = sidecar.read(self.directory, session_id)
            new = sidecar.Sidecar(side.tags, side.notes if notes is None else sidecar.check_text("notes", notes),
                                  side.operator if operator is None else sidecar.check_text("operator", operator, 200))
            sidecar.write(self.directory, session_id, new)
            self.refresh()
            return self.get(session_id)

    # ------------------------------------------------------------------ trend
    def trend(self, name: str, by: str = "date", query: str = "") -> list[TrendPoint]:
        """Field ``name`` (a number) of the sessions matching ``query``, each with its group:
        its day (``by="date"``), or the value of a key of its recorded configuration
        (``by="loop.mpc.lam_st"``; ``(none)`` when it has none). Sessions without the value
        are left out. In start order; each point with the figure's interval when the library
        keeps one (``epm_lo``/``epm_hi`` ...)."""
        f = field(name, "trend: field")
        if f.kind != "number":
            raise QueryError(f"trend: {name!r} is not a number; numbers: "
                             + ", ".join(k for k, v in FIELDS.items() if v.kind == "number"))
        if by != "date" and not all(by.split(".")):
            raise QueryError(f"--by {by!r}: expected date or a configuration key such as loop.mpc.lam_st")
        rows = self.find(query, "start")
        tomls: dict[str, Any] = {}
        if by != "date":
            import tomllib

            with self._lock:
                conn = self._connect()
                for digest, text in conn.execute("SELECT hash, toml FROM configs"):
                    try:
                        tomls[digest] = tomllib.loads(text)
                    except tomllib.TOMLDecodeError:
                        tomls[digest] = {}
        out = []
        for r in rows:
            v = self._value(r, f.column)
            if v is None:
                continue
            if by == "date":
                group = r.date or "(no date)"
            else:
                node: Any = tomls.get(r.config_hash, {})
                for key in by.split("."):
                    node = node.get(key) if isinstance(node, dict) else None
                group = "(none)" if node is None or isinstance(node, dict) else str(node)
            lo, hi = r.figures.get(f.column + "_lo"), r.figures.get(f.column + "_hi")
            out.append(TrendPoint(r.id, r.start, group, float(v), None if lo is None else float(lo),
                                  None if hi is None else float(hi)))
        return out

    @staticmethod
    def _value(r: Row, column: str) -> float | None:
        if column in r.figures:
            return r.figures[column]
        v = {"start": r.start, "duration": r.duration, "size": r.size, "parts": r.parts,
             "segments": len(r.segments), "ntags": len(r.tags), "markers": r.markers,
             "failsafes": len(r.failsafes)}.get(column)
        return None if v is None else float(v)
