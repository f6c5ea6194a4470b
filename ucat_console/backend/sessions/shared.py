"""One open reader per session file for everyone in the process who reviews it.

Pages reviewing the same session share one :class:`~.reader.SessionParts`: its open files,
summaries, metadata and event index are held once (in the console's memory budget,
:mod:`~.limits`), however many pages play it. A reader reads with ``os.pread`` and keeps
no position, so its users' players may read it from their own threads at once.

:meth:`SharedReaders.acquire` opens a session or hands out the reader already open for the
same files (the same parts, unchanged: a file repaired or rewritten since is opened anew);
:meth:`SharedReaders.release` gives it back, and the last user's release closes it. The
console's supervisor owns one (``readers``), with the console's memory budget.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

from ucat_console.backend.sessions import files
from ucat_console.backend.sessions.limits import MemoryBudget
from ucat_console.backend.sessions.reader import SessionParts

def _identity(paths: list[Path]) -> tuple:
    """The files as they are now: each path with its device, inode, size and modification time."""
    out = []
    for p in paths:
        st = os.stat(p)
        out.append((str(p), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns))
    return tuple(out)


class SharedReaders:
    """The open readers of one console, all reading within its ``budget`` (module docstring)."""

    def __init__(self, budget: MemoryBudget | None = None) -> None:
        self.budget = budget if budget is not None else MemoryBudget()
        self._lock = threading.Lock()
        self._open: dict[tuple, list] = {}  # the files' identity -> [reader, users]

    def acquire(self, session: str | Path, directory: str | Path | None = None) -> SessionParts:
        """The reader of ``session`` (a session id or a part file, as :class:`SessionParts`
        takes it), shared with every other user of the same files; :meth:`release` it."""
        root = files.sessions_dir(directory)
        key = _identity(files.session_files(session, root))
        with self._lock:
            entry = self._open.get(key)
            if entry is not None:
                entry[1] += 1
                return entry[0]
            # opened under the lock: two pages opening one session at once open it once
            reader = SessionParts(session, root, budget=self.budget)
            self._open[key] = [reader, 1]
            return reader

    def release(self, reader: SessionParts) -> None:
        """One user of ``reader`` is done with it (the last one closes it)."""
        with self._lock:
            for key, entry in self._open.items():
                if entry[0] is reader:
                    entry[1] -= 1
                    if entry[1] > 0:
                        return
                    del self._open[key]
                    break
            else:
                return
        reader.close()

    def users(self, reader: SessionParts) -> int:
        """How many users hold ``reader`` (0: not a shared reader, or closed)."""
        with self._lock:
            return next((e[1] for e in self._open.values() if e[0] is reader), 0)
