"""Review markers: notes added while reviewing a session, kept beside it.

A session file is never modified after recording; markers added during review go to the
sidecar ``<session id>.markers.json`` in the same directory::

    {"session": "<id>", "markers": [{"t": 12.5, "note": "fin 2 stalls", "created": 1.7e9}]}

``t`` is on the recorded stream's clock (seconds, like the messages' ``t``), ``created``
the wall-clock time (UNIX seconds) the marker was added. The file is replaced atomically.
"""

from __future__ import annotations

import json
import math
import os
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from ucat_console.backend.sessions import files


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


class MarkerStore:
    """The markers of one session, loaded from and saved to its sidecar file."""

    def __init__(self, directory: str | Path, session_id: str) -> None:
        self.session_id = session_id
        self.path = files.markers_path(Path(directory), session_id)
        self._lock = threading.Lock()
        self._markers: list[Marker] = self._load()

    def _load(self) -> list[Marker]:
        if not self.path.exists():
            return []
        try:
            doc = json.loads(self.path.read_text())
        except (OSError, ValueError) as e:
            raise ValueError(f"{self.path}: not a markers file ({e})") from None
        if not isinstance(doc, dict) or not isinstance(doc.get("markers"), list):
            raise ValueError(f"{self.path}: not a markers file (no \"markers\" list)")
        if doc.get("session") != self.session_id:
            raise ValueError(
                f"{self.path}: markers of session {doc.get('session')!r}, not {self.session_id!r}"
            )
        out = [_marker(m, f"{self.path}: markers[{i}]") for i, m in enumerate(doc["markers"])]
        return sorted(out, key=lambda m: m.t)

    @property
    def markers(self) -> list[Marker]:
        return list(self._markers)

    def add(self, t: float, note: str = "") -> Marker:
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
            raise ValueError(f"t: expected a finite time, got {t!r}")
        if not isinstance(note, str):
            raise ValueError(f"note: expected text, got {note!r}")
        m = Marker(float(t), note, time.time())
        with self._lock:
            self._markers = sorted(self._markers + [m], key=lambda x: x.t)
            self._save()
        return m

    def remove(self, marker: Marker) -> None:
        with self._lock:
            if marker not in self._markers:
                raise ValueError(f"no such marker: {marker!r}")
            self._markers = [m for m in self._markers if m != marker]
            self._save()

    def _save(self) -> None:
        doc = {"session": self.session_id, "markers": [asdict(m) for m in self._markers]}
        tmp = self.path.with_name(self.path.name + ".tmp")
        tmp.write_text(json.dumps(doc, indent=1))
        os.replace(tmp, self.path)
