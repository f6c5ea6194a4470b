"""Review markers: notes added while reviewing a session, kept beside it.

A session file is never modified after recording; markers added during review go to the
sidecar ``<session id>.markers.json`` in the same directory::

    {"session": "<id>", "markers": [{"t": 12.5, "note": "fin 2 stalls", "created": 1.7e9}]}

``t`` is on the recorded stream's clock (seconds, like the messages' ``t``), ``created``
the wall-clock time (UNIX seconds) the marker was added. The file is written to a
temporary file beside it and renamed over it, so it is always whole. A note holds at most
:data:`MAX_NOTE_BYTES` bytes as the file stores it (UTF-8, escapes counted) and a session at
most :data:`MAX_MARKERS` markers, so the sidecar stays below about 21 MB (10,000 x (2 kB +
the marker's 70 bytes of JSON)) whoever adds to it.
"""

from __future__ import annotations

import json
import math
import os
import stat
import threading
import time
import weakref
from dataclasses import asdict, dataclass
from pathlib import Path

from ucat_console.backend.sessions import codec, files

#: the longest note of a review marker (bytes, UTF-8)
MAX_NOTE_BYTES = 2048
#: the most markers a session keeps
MAX_MARKERS = 10_000
#: the largest sidecar read (bytes): the most markers with the longest notes, indented
MAX_FILE_BYTES = MAX_MARKERS * (MAX_NOTE_BYTES + 200)


@dataclass(frozen=True)
class Marker:
    t: float
    note: str
    created: float


def _marker(obj: object, where: str) -> Marker:
    if not isinstance(obj, dict) or set(obj) != {"t", "note", "created"}:
        raise ValueError(f"{where}: expected an object with t, note, created, got {obj!r}")
    t, note, created = obj["t"], obj["note"], obj["created"]
    for name, v in (("t", t), ("created", created)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"{where}.{name}: expected a finite number, got {v!r}")
    if not isinstance(note, str):
        raise ValueError(f"{where}.note: expected text, got {note!r}")
    return Marker(float(t), note, float(created))


def check_note(note: object) -> str:
    """``note`` when it is text of at most :data:`MAX_NOTE_BYTES` bytes as the sidecar stores
    it (UTF-8 JSON: a quote or a control character takes its escape's bytes), else
    ValueError saying why."""
    if not isinstance(note, str):
        raise ValueError(f"marker note: expected text, got {type(note).__name__}")
    try:
        n = len(json.dumps(note, ensure_ascii=False).encode("utf-8")) - 2  # without the quotes
    except UnicodeEncodeError:
        raise ValueError("marker note: not valid text (a lone surrogate)") from None
    if n > MAX_NOTE_BYTES:
        raise ValueError(f"marker note: {n} bytes, over the limit of {MAX_NOTE_BYTES} bytes")
    return note


_SHARED: weakref.WeakValueDictionary[Path, MarkerStore] = weakref.WeakValueDictionary()
_SHARED_LOCK = threading.Lock()


class MarkerStore:
    """The markers of one session, loaded from and saved to its sidecar file.

    Everyone in one process reviewing a session should use the same store
    (:meth:`shared`), so that markers added from several pages all reach the file."""

    @classmethod
    def shared(cls, directory: str | Path, session_id: str) -> MarkerStore:
        """The one store of ``session_id`` in this process (made when first asked for)."""
        key = files.markers_path(Path(directory), session_id).resolve()
        with _SHARED_LOCK:
            store = _SHARED.get(key)
            if store is None:
                store = cls(directory, session_id)
                _SHARED[key] = store
            return store

    def __init__(self, directory: str | Path, session_id: str) -> None:
        self.session_id = session_id
        self.path = files.markers_path(Path(directory), session_id)
        self._lock = threading.Lock()
        self._markers: list[Marker] = self._load()

    def _load(self) -> list[Marker]:
        p = self.path
        if not p.exists() and not p.is_symlink():
            return []
        if not p.resolve().is_relative_to(p.parent.resolve()):
            raise ValueError(f"{p}: a symbolic link out of the sessions directory: not followed")
        try:
            st = os.stat(p)  # before opening: a pipe would block the open
            if not stat.S_ISREG(st.st_mode):
                raise ValueError("not a regular file")
            if st.st_size > MAX_FILE_BYTES:
                raise ValueError(f"{st.st_size} bytes, more than a markers file holds ({MAX_FILE_BYTES})")
            with open(p, "rb") as fh:
                data = fh.read(MAX_FILE_BYTES + 1)
            doc = codec.load_json(data, "JSON")
        except (OSError, ValueError) as e:
            raise ValueError(f"{p}: not a markers file ({e})") from None
        if not isinstance(doc, dict) or not isinstance(doc.get("markers"), list):
            raise ValueError(f"{self.path}: not a markers file (no \"markers\" list)")
        if doc.get("session") != self.session_id:
            raise ValueError(
                f"{self.path}: markers of session {codec.short(doc.get('session'))}, not {self.session_id!r}"
            )
        if len(doc["markers"]) > MAX_MARKERS:
            raise ValueError(f"{self.path}: {len(doc['markers'])} markers, more than the limit of {MAX_MARKERS}")
        out = [_marker(m, f"{self.path}: markers[{i}]") for i, m in enumerate(doc["markers"])]
        return sorted(out, key=lambda m: m.t)

    @property
    def markers(self) -> list[Marker]:
        return list(self._markers)

    def add(self, t: float, note: str = "") -> Marker:
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
            raise ValueError(f"t: expected a finite time, got {t!r}")
        note = check_note(note)
        m = Marker(float(t), note, time.time())
        with self._lock:
            if len(self._markers) >= MAX_MARKERS:
                raise ValueError(f"markers: session {self.session_id} has the most markers a session "
                                 f"keeps ({MAX_MARKERS}); remove some first")
            new = sorted(self._markers + [m], key=lambda x: x.t)
            self._save(new)  # first: a failed write leaves the markers as they were
            self._markers = new
        return m

    def remove(self, marker: Marker) -> None:
        with self._lock:
            if marker not in self._markers:
                raise ValueError(f"no such marker: {marker!r}")
            new = [m for m in self._markers if m != marker]
            self._save(new)
            self._markers = new

    def _save(self, markers: list[Marker]) -> None:
        doc = {"session": self.session_id, "markers": [asdict(m) for m in markers]}
        tmp = self.path.with_name(self.path.name + ".tmp")
        try:
            with open(tmp, "w", encoding="utf-8") as fh:
                json.dump(doc, fh, indent=1, ensure_ascii=False)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
