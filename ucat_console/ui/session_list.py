"""The sessions folder's listing, shared by every page and read again only when the folder changed.

Listing the folder reads each file's summary (:func:`ucat_console.backend.sessions.index.list_sessions`):
with two dozen sessions of a minute each that is about a quarter of a second. Every page lists
it when it connects, its Review tab on "Refresh list", and its Session tab, Review tab and comparison when a recording ends;
:class:`SessionList` keeps the last listing with the folder's signature (each entry's name,
size and modification time, one ``stat`` each) and lists again only when that has changed.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

from ucat_console.backend.sessions import index
from ucat_console.backend.sessions.limits import MemoryBudget


class SessionList:
    """The listing of one sessions folder (module docstring); thread-safe."""

    def __init__(self, directory: str | Path, budget: MemoryBudget | None = None) -> None:
        self.directory = Path(directory)
        self.budget = budget if budget is not None else MemoryBudget()  # what reading a file may hold
        self._lock = threading.Lock()
        self._key: tuple | None = None
        self._listing = index.Listing([], [])
        self.listings = 0  # times the folder was read

    def _signature(self) -> tuple:
        try:
            with os.scandir(self.directory) as it:
                out = []
                for e in it:
                    try:
                        st = e.stat(follow_symlinks=False)
                    except OSError:
                        continue
                    out.append((e.name, st.st_size, st.st_mtime_ns))
        except OSError:
            return ()
        return tuple(sorted(out))

    def listing(self) -> index.Listing:
        """Every session in the folder and the entries not read (as :func:`index.scan` gives them)."""
        with self._lock:
            key = self._signature()
            if key != self._key:
                self._listing = index.scan(self.directory, self.budget)
                self._key = key
                self.listings += 1
            return index.Listing(list(self._listing.sessions), list(self._listing.skipped))

    def sessions(self) -> list[index.SessionInfo]:
        """Every session in the folder (as :func:`index.list_sessions` gives them)."""
        return self.listing().sessions
