"""The session index: what is in the sessions directory, read from summaries only.

A finished part is described from its summary section and metadata records (a few
kilobytes read from the end of the file); a truncated part from the metadata records at its
start (the recorder writes them before any message), with its duration unknown until it is
repaired (or, while a recorder writes it, ``recording``). No message is decoded.

Which session a file belongs to, and as which part, is decided by its name alone (the
recorder's ``<session id>_<part>.mcap``), never by what its metadata claims: a file whose
metadata names another session or part is listed under its name and marked unreadable
(opening it is refused the same way), and a file whose name is not a part name is a
recording of its own, listed under its file name. Symbolic links are never read as parts:
the listing skips every one and says so (a file a link points to inside the folder is
listed under its own name).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

from mcap.records import Chunk, Metadata
from mcap.stream_reader import StreamReader

from ucat_console.backend.sessions import codec, files, writing
from ucat_console.backend.sessions.limits import MemoryBudget
from ucat_console.backend.sessions.mcap_read import MAGIC, TruncatedSessionError, record_limit
from ucat_console.backend.sessions.reader import SessionReader
from ucat_console.telemetry.channels import EVENTS

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PartInfo:
    path: Path
    session_id: str
    part: int
    size: int  # bytes
    truncated: bool  # no summary: needs ``repair``
    start: float | None  # UNIX seconds of the first message (None when unknown)
    duration: float | None  # s (None when truncated)
    messages: int | None
    events: int | None
    notes: str
    error: str = ""  # why the part could not be read ("" when it could)
    recording: bool = False  # a recorder is writing it now (it has no summary yet)
    original_of: str = ""  # the repaired file whose original this is ("" when it is none)

    @property
    def repairable(self) -> bool:
        """Truncated, and neither being recorded nor an original a repair kept."""
        return self.truncated and not self.recording and not self.original_of


@dataclass(frozen=True)
class SessionInfo:
    session_id: str
    parts: tuple[PartInfo, ...]

    @property
    def size(self) -> int:
        return sum(p.size for p in self.parts)

    @property
    def duration(self) -> float | None:
        """Sum of the parts' durations (None when any part is truncated)."""
        if any(p.duration is None for p in self.parts):
            return None
        return sum(p.duration for p in self.parts if p.duration is not None)

    @property
    def truncated(self) -> bool:
        return any(p.truncated for p in self.parts)

    @property
    def recording(self) -> bool:
        return any(p.recording for p in self.parts)

    @property
    def events(self) -> int | None:
        if any(p.events is None for p in self.parts):
            return None
        return sum(p.events for p in self.parts if p.events is not None)

    @property
    def notes(self) -> str:
        for p in reversed(self.parts):
            if p.notes:
                return p.notes
        return ""

    @property
    def start(self) -> float | None:
        return self.parts[0].start if self.parts else None


def _leading_metadata(path: Path, budget: MemoryBudget) -> dict[str, dict[str, str]]:
    """Metadata records before the first chunk (read without the summary)."""
    out: dict[str, dict[str, str]] = {}
    with open(path, "rb") as fh:
        try:
            for rec in StreamReader(fh, emit_chunks=True, record_size_limit=record_limit(budget.config)).records:
                if isinstance(rec, Metadata):
                    out[rec.name] = dict(rec.metadata)
                elif isinstance(rec, Chunk):
                    break
        except Exception:  # a file cut inside its first records
            pass
    return out


def listed_as(path: Path) -> tuple[str, int]:
    """(session, part) a file is listed as, from its name: a part name's session id and part
    number; any other file is a recording of its own, part 1, under its file name."""
    return files.parse_part_name(path) or (path.name, 1)


def _disagreement(path: Path, session: dict[str, str]) -> str:
    """Why the metadata of a file named as a part contradicts its name ("" when it does not)."""
    parsed = files.parse_part_name(path)
    if parsed is None:
        return ""
    sid, part = parsed
    if session.get("id", sid) != sid:
        return f"its metadata names session {codec.short(session['id'])}, not {sid!r} as its name does"
    if session.get("part", str(part)) != str(part):
        return f"its metadata names part {codec.short(session['part'])}, not {part} as its name does"
    return ""


def part_info(path: str | Path, directory: str | Path | None = None,
              budget: MemoryBudget | None = None) -> PartInfo:
    """Describe one session file from its summary (or its first records when truncated),
    read within ``budget`` (default: one of its own); its session and part are those of its
    name (module docstring)."""
    budget = budget if budget is not None else MemoryBudget()
    p = files.inside_sessions(path, directory)
    size = p.stat().st_size
    sid, part = listed_as(p)
    original_of = files.original_of(p.name)
    try:
        with SessionReader(p, p.parent, budget=budget) as r:
            counts = r.message_counts()
            return PartInfo(
                path=p, session_id=sid, part=part, size=size, truncated=False,
                start=r.start_ns * 1e-9 if r.message_count else None,
                duration=r.duration, messages=r.message_count,
                events=counts.get(EVENTS, 0), notes=r.notes,
                error=_disagreement(p, r.metadata.get(files.META_SESSION, {})), original_of=original_of,
            )
    except TruncatedSessionError:
        with open(p, "rb") as fh:
            is_mcap = fh.read(len(MAGIC)) == MAGIC
        meta = _leading_metadata(p, budget) if is_mcap else {}
        session = meta.get(files.META_SESSION, {})
        started = session.get("started_ns", "")
        return PartInfo(
            path=p, session_id=sid, part=part, size=size, truncated=True,
            start=int(started) * 1e-9 if started.isdigit() else None,
            duration=None, messages=None, events=None,
            notes=meta.get(files.META_NOTES, {}).get("text", ""),
            error=_disagreement(p, session), recording=writing.being_written(p), original_of=original_of,
        )
    except (ValueError, OSError) as e:
        return PartInfo(p, sid, part, size, False, None, None, None, None, "", str(e), original_of=original_of)


@dataclass(frozen=True)
class Skipped:
    """An entry of the sessions directory that is not read, and why."""

    name: str  # printable: characters that are not are escaped
    why: str


@dataclass(frozen=True)
class Listing:
    sessions: list[SessionInfo]
    skipped: list[Skipped]


def _why_skipped(entry: os.DirEntry, root: Path) -> str:
    """Why a ``*.mcap`` entry of the directory is not read ("" when it is)."""
    if not entry.name.isprintable():
        return "its name holds characters that are not printable (rename it to read it)"
    try:
        if entry.is_symlink():
            target = Path(entry.path).resolve()
            if not target.is_relative_to(root):
                return f"a symbolic link out of the sessions directory (to {files.printable(str(target))}): not followed"
            return (f"a symbolic link (to {files.printable(target.name)}): not followed; a session file "
                    "is listed under its own name")
        if not entry.is_file(follow_symlinks=False):
            return "not a regular file"
    except (OSError, RuntimeError) as e:  # a link loop, permissions
        return f"unreadable ({type(e).__name__}: {e})"
    return ""


def scan(directory: str | Path | None = None, budget: MemoryBudget | None = None) -> Listing:
    """Every session in the directory (oldest first, parts in order, grouped by their file
    names) and the ``*.mcap`` entries that are not read: symbolic links (never followed),
    what is not a regular file (a directory, a pipe, a device), names that cannot be shown.
    Each file is read within ``budget`` (default: one of the listing's own)."""
    budget = budget if budget is not None else MemoryBudget()
    root = files.sessions_dir(directory)
    if not root.is_dir():
        return Listing([], [])
    by_id: dict[str, list[PartInfo]] = {}
    skipped: list[Skipped] = []
    with os.scandir(root) as it:
        entries = sorted((e for e in it if e.name.endswith(files.SUFFIX)), key=lambda e: e.name)
    for entry in entries:
        why = _why_skipped(entry, root)
        if why:
            skipped.append(Skipped(files.printable(entry.name), why))
            continue
        info = part_info(root / entry.name, root, budget)
        by_id.setdefault(info.session_id, []).append(info)
    sessions = [
        SessionInfo(sid, tuple(sorted(ps, key=lambda x: x.part))) for sid, ps in by_id.items()
    ]
    sessions.sort(key=lambda s: (s.start is None, s.start or 0.0, s.session_id))
    return Listing(sessions, skipped)


def list_sessions(directory: str | Path | None = None, budget: MemoryBudget | None = None) -> list[SessionInfo]:
    """Every session in the directory, oldest first, parts in order (:func:`scan` also
    says what it skipped)."""
    return scan(directory, budget).sessions


def session_parts(session_id: str, directory: str | Path | None = None) -> list[Path]:
    """The part files of a session, in order (ValueError when there are none).

    Lists what is there; :class:`~ucat_console.backend.sessions.reader.SessionParts`, which
    reads a session as one, also refuses a gap in the part numbers.
    """
    root = files.sessions_dir(directory)
    parts = files.part_paths(session_id, root)
    if not parts:
        raise ValueError(f"session {session_id!r}: no files in {root}")
    return [p for _, p in sorted(parts.items())]
