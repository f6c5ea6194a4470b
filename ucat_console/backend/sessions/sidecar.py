"""A session's library sidecar: the tags, notes and operator's name given after recording.

A finished session file is never rewritten (the mcap library cannot append a metadata record
to a finished file in place, and rewriting recorded data to change a note is what the
recorder's crash safety exists to avoid), so what is said about a session after it was
recorded lives beside its parts in ``<session id>.meta.json``::

    {"session": "<id>", "tags": ["pool-3"], "notes": "weak fin 2", "operator": "Kati",
     "updated": 1796550000.0}

Each key is optional: a missing ``notes`` means "the recorded notes stand", a given one
replaces them wherever the session is shown (the library, ``sessions info``). The file is
written to a temporary file beside it and renamed over it, so it is always whole. A file
that cannot be read or holds something else is an error naming the file and the key,
never read as empty.
"""

from __future__ import annotations

import json
import os
import re
import time
from dataclasses import dataclass
from pathlib import Path

SUFFIX = ".meta.json"
#: the longest notes kept (characters; as the recorder's)
MAX_NOTES = 2000
#: the most tags a session keeps
MAX_TAGS = 64
#: the largest sidecar read (bytes)
MAX_FILE_BYTES = 256 * 1024
_TAG = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.:-]{0,63}$")
_KEYS = {"session", "tags", "notes", "operator", "updated"}


@dataclass(frozen=True)
class Sidecar:
    """What a sidecar says (``notes``/``operator`` None: not given, the recording's stand)."""

    tags: tuple[str, ...] = ()
    notes: str | None = None
    operator: str | None = None


def path_of(directory: Path, session_id: str) -> Path:
    return directory / f"{session_id}{SUFFIX}"


def check_tag(tag: object) -> str:
    """``tag`` when it is 1-64 letters, digits, '_', '.', ':' or '-' starting with a letter or
    digit, else ValueError saying so."""
    if not isinstance(tag, str) or not _TAG.match(tag):
        raise ValueError(f"tag {tag!r}: a tag is 1-64 letters, digits, '_', '.', ':' or '-', "
                         "starting with a letter or digit (e.g. pool-3)")
    return tag


def check_text(name: str, text: object, most: int = MAX_NOTES) -> str:
    if not isinstance(text, str) or len(text) > most:
        raise ValueError(f"{name}: expected text of at most {most} characters, got "
                         f"{type(text).__name__} of {len(text) if isinstance(text, str) else '?'}")
    return text


def read(directory: Path, session_id: str) -> Sidecar:
    """The session's sidecar (an empty one when there is no file); ValueError naming the file
    when it cannot be read or is not one."""
    p = path_of(directory, session_id)
    if p.is_symlink():
        raise ValueError(f"{p}: a symbolic link: not followed (a sidecar is a file beside the session)")
    try:
        with open(p, "rb") as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)
    except FileNotFoundError:
        return Sidecar()
    if len(raw) > MAX_FILE_BYTES:
        raise ValueError(f"{p}: larger than {MAX_FILE_BYTES} bytes: not a session sidecar")
    try:
        obj = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{p}: not JSON ({e})") from None
    if not isinstance(obj, dict):
        raise ValueError(f"{p}: expected an object with tags, notes, operator")
    extra = set(obj) - _KEYS
    if extra:
        raise ValueError(f"{p}: unknown key(s) {', '.join(sorted(extra))}; known: {', '.join(sorted(_KEYS))}")
    if obj.get("session", session_id) != session_id:
        raise ValueError(f"{p}: names session {obj['session']!r}, not {session_id!r} as its name does")
    tags = obj.get("tags", [])
    if not isinstance(tags, list) or len(tags) > MAX_TAGS:
        raise ValueError(f"{p}: tags: expected a list of at most {MAX_TAGS} tags")
    try:
        checked = tuple(check_tag(t) for t in tags)
        notes = None if obj.get("notes") is None else check_text("notes", obj["notes"])
        operator = None if obj.get("operator") is None else check_text("operator", obj["operator"], 200)
    except ValueError as e:
        raise ValueError(f"{p}: {e}") from None
    return Sidecar(tuple(dict.fromkeys(checked)), notes, operator)


def write(directory: Path, session_id: str, side: Sidecar) -> Path:
    """Write the sidecar whole (a temporary file renamed over it); its path."""
    for t in side.tags:
        check_tag(t)
    if len(side.tags) > MAX_TAGS:
        raise ValueError(f"tags: at most {MAX_TAGS} a session, got {len(side.tags)}")
    obj: dict[str, object] = {"session": session_id, "tags": list(side.tags)}
    if side.notes is not None:
        obj["notes"] = check_text("notes", side.notes)
    if side.operator is not None:
        obj["operator"] = check_text("operator", side.operator, 200)
    obj["updated"] = time.time()
    p = path_of(directory, session_id)
    tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(obj, fh, ensure_ascii=False, indent=1)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    finally:
        tmp.unlink(missing_ok=True)
    return p


def edit_tags(tags: tuple[str, ...], changes: list[str]) -> tuple[str, ...]:
    """``tags`` after ``changes``: ``+tag`` (or a bare ``tag``) adds, ``-tag`` removes;
    ValueError naming a bad change."""
    out = list(tags)
    for c in changes:
        if not isinstance(c, str) or not c:
            raise ValueError(f"tag change {c!r}: expected +TAG or -TAG")
        add = c[0] != "-"
        tag = check_tag(c[1:] if c[0] in "+-" else c)
        if add and tag not in out:
            out.append(tag)
        elif not add and tag in out:
            out.remove(tag)
    return tuple(out)


def is_sidecar(name: str) -> bool:
    return name.endswith(SUFFIX)


def session_of(name: str) -> str:
    return name.removesuffix(SUFFIX)

