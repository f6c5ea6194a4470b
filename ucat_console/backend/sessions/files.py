"""Where session files live, what they are called, and the metadata records they hold;
which files a session id or a named part stands for (:func:`session_paths`).

The sessions directory is the one a run is given (``run --sessions-dir``, a command's
``--dir``, ``console.sessions_dir`` in the configuration), else the folder the environment
variable ``UCAT_CONSOLE_SESSIONS`` names, else ``sessions/`` in the user's data folder
(``~/.local/share/ucat-console/sessions`` on Linux: platformdirs), never the installed package.

One session is one or more MCAP files (parts) in the sessions directory, named
``<session id>_<part>.mcap`` with a three-digit part number from 001; the session id is
``YYYYmmdd-HHMMSS`` (UTC, at the start) followed by ``-<label>`` when one is given. Review
markers live beside them in ``<session id>.markers.json``. A repair keeps the file it
rewrote as ``<name>.orig.mcap`` (``<session id>_001.orig.mcap``): listed, read alone.

Metadata records (MCAP metadata, string values), written at the start of every part:

    session   id, part, started_ns (wall clock), epoch_offset (s, repr), clock
    config    toml: the run's configuration as TOML text; name: the name it was loaded by
              (a shipped configuration's, a file's name, ``default``; absent when unknown)
    weights   one key per MPC weight (lam_f, lam_st, lam_a, lam_d), values repr(float)
    version   ucat_console, mcap, python
    notes     text: the operator's notes (a later record replaces an earlier one)
"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path

import platformdirs

#: the environment variable naming the sessions directory when a run is given none
SESSIONS_ENV = "UCAT_CONSOLE_SESSIONS"

SUFFIX = ".mcap"
#: the original of a repaired file, kept beside it: ``<name without .mcap>.orig.mcap``
ORIGINAL_SUFFIX = ".orig" + SUFFIX
MARKERS_SUFFIX = ".markers.json"
PROFILE = "ucat_console"

META_SESSION = "session"
META_CONFIG = "config"
META_WEIGHTS = "weights"
META_VERSION = "version"
META_NOTES = "notes"
#: what each transform frame of the file is (REP 103/105 names; foxglove.FRAME_NOTES)
META_FRAMES = "frames"

_LABEL = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")
_PART = re.compile(r"^(?P<session>.+)_(?P<part>\d{3,})\.mcap$")


def new_session_id(wall_time: float | None = None, label: str = "") -> str:
    """A session id from the wall clock (UTC) and an optional label."""
    if label and not _LABEL.match(label):
        raise ValueError(
            f"label: {label!r} must be 1-64 letters, digits, '_', '.' or '-', starting "
            "with a letter or digit"
        )
    wall = time.time() if wall_time is None else wall_time
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime(wall))
    return f"{stamp}-{label}" if label else stamp


def part_name(session_id: str, part: int) -> str:
    return f"{session_id}_{part:03d}{SUFFIX}"


def parse_part_name(path: str | Path) -> tuple[str, int] | None:
    """(session id, part) from a part file's name, None when it is not one."""
    m = _PART.match(Path(path).name)
    return (m["session"], int(m["part"])) if m else None


def original_name(name: str) -> str:
    """The name a repair keeps the original of file ``name`` under."""
    return name.removesuffix(SUFFIX) + ORIGINAL_SUFFIX


def original_of(name: str) -> str:
    """The name of the file whose original file ``name`` is ("" when it is not one)."""
    return name.removesuffix(ORIGINAL_SUFFIX) + SUFFIX if name.endswith(ORIGINAL_SUFFIX) else ""


def markers_path(directory: Path, session_id: str) -> Path:
    return directory / f"{session_id}{MARKERS_SUFFIX}"


def printable(text: str) -> str:
    """``text`` with each character that is not printable escaped (a file name shown on a
    terminal or a page: no control characters; undecodable bytes as ``\\udcXX``)."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


def default_sessions_dir() -> Path:
    """Where recordings go when a run is given no directory (module docstring)."""
    env = os.environ.get(SESSIONS_ENV, "")
    if env:
        return Path(env)
    return platformdirs.user_data_path("ucat-console") / "sessions"


def sessions_dir(directory: str | Path | None = None) -> Path:
    """The sessions directory (default: :func:`default_sessions_dir`), resolved."""
    return Path(default_sessions_dir() if directory is None else directory).expanduser().resolve()


def inside_sessions(path: str | Path, directory: str | Path | None = None) -> Path:
    """``path`` resolved, or ValueError when it lies outside the sessions directory."""
    root = sessions_dir(directory)
    p = Path(path).expanduser().resolve()
    if not p.is_relative_to(root):
        raise ValueError(f"{path}: outside the sessions directory {root}")
    return p


def session_path(path: str | Path, directory: str | Path | None = None, *, confined: bool = True) -> Path:
    """``path`` resolved. ``confined`` (the default: what a page names) refuses a path
    outside the sessions directory (:func:`inside_sessions`); ``confined=False`` is for a
    file the person at the shell named (the command line, ``ucat_console.sessions.open``),
    read wherever it is."""
    return inside_sessions(path, directory) if confined else Path(path).expanduser().resolve()


def part_paths(session_id: str, directory: str | Path | None = None) -> dict[int, Path]:
    """The part files of ``session_id`` in ``directory``, by part number (empty when none):
    the regular files named ``<session_id>_<part>.mcap`` (a symbolic link is never a part).

    Two files naming the same part (``_001`` and ``_0001``) raise ValueError naming both.
    """
    root = sessions_dir(directory)
    found: dict[int, Path] = {}
    if not root.is_dir():
        return found
    for path in sorted(root.iterdir()):
        parsed = parse_part_name(path)
        if parsed is None or parsed[0] != session_id or path.is_symlink() or not path.is_file():
            continue
        if parsed[1] in found:
            raise ValueError(f"{path}: part {parsed[1]} of session {session_id!r} is also "
                             f"{found[parsed[1]].name}; keep one of the two")
        found[parsed[1]] = path
    return found


def part_sequence(session_id: str, folder: Path) -> list[Path]:
    """The part files of a session in part order; ValueError naming the first missing one."""
    found = part_paths(session_id, folder)
    if not found:
        raise ValueError(f"session {session_id!r}: no files in {folder}")
    for n in range(1, max(found) + 1):
        if n not in found:
            have = ", ".join(p.name for _, p in sorted(found.items()))
            raise ValueError(f"{folder / part_name(session_id, n)}: no such file: part {n} "
                             f"of session {session_id!r} is missing (found {have})")
    return [found[n] for n in sorted(found)]


def named_file(session: str | Path, root: Path) -> Path | None:
    """The file ``session`` names (as given, else inside ``root``), None when it names none.

    A ``Path``, or text holding a path separator or ending in ``.mcap``, names a file
    (ValueError when there is none); any other text is a session id (None).
    """
    text = str(session)
    is_path = isinstance(session, Path) or "/" in text or "\\" in text
    if not is_path and not text.endswith(SUFFIX):
        return None
    p = Path(text).expanduser()
    for candidate in (p,) if p.is_absolute() else (p, root / p):
        if candidate.is_file():
            return candidate
    raise ValueError(f"{session}: no such session file")


def session_paths(session: str | Path, root: Path, confined: bool = True) -> tuple[str | None, list[Path]]:
    """(session id, part files in order) named by a session id or by one of its parts;
    the id is None for a file whose name is not a part name (it is read alone). A named
    file outside ``root`` is refused when ``confined`` (:func:`session_path`)."""
    given = named_file(session, root)
    if given is None:
        sid = str(session)
        if not sid:
            raise ValueError("session: no session id given")
        return sid, part_sequence(sid, root)
    p = session_path(given, root, confined=confined)
    parsed = parse_part_name(p)
    if parsed is None:
        return None, [p]
    return parsed[0], part_sequence(parsed[0], p.parent)


def session_files(session: str | Path, directory: str | Path | None = None) -> list[Path]:
    """The part files :class:`~.reader.SessionParts` opens for ``session``, in part order."""
    return session_paths(session, sessions_dir(directory))[1]
