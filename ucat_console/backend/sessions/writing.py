"""Which session files a recorder is writing, so that nothing rewrites one under it.

The recorder holds every part file it writes (:func:`hold` when it opens it,
:func:`let_go` once it is closed and, after a failed write, cut back): in this process by
its path, and for other processes with an advisory lock (``flock``, exclusive) on the open
file. The kernel drops that lock when the file's last descriptor is closed or the process
ends (a crash, SIGKILL), so it never outlives the writer. :func:`being_written` asks both:
``repair`` refuses such a file, from the Review tab or from ``ucat-console sessions
repair`` in a shell beside a console that is recording. On a file system without
``flock`` (or on a platform without ``fcntl``) only this process's register is asked.
"""

from __future__ import annotations

import logging
import os
import threading
from pathlib import Path
from typing import IO

try:
    import fcntl
except ImportError:  # not a POSIX platform: the register alone
    fcntl = None  # type: ignore[assignment]

log = logging.getLogger(__name__)

_lock = threading.Lock()
_held: set[Path] = set()


def hold(path: Path, file: IO[bytes]) -> None:
    """The recorder writes ``file`` (at ``path``) from now on."""
    with _lock:
        _held.add(path.resolve())
    if fcntl is None:
        return
    try:
        fcntl.flock(file.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as e:
        log.warning("%s: no advisory lock on the recording (%s): a repair from another process "
                    "cannot tell that it is being written", path.name, e)


def let_go(path: Path) -> None:
    """The recorder is done with ``path`` (its lock went with the file's last descriptor)."""
    with _lock:
        _held.discard(path.resolve())


def being_written(path: str | Path) -> bool:
    """Whether a recorder, in this process or another, is writing ``path``."""
    p = Path(path).resolve()
    with _lock:
        if p in _held:
            return True
    if fcntl is None:
        return False
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)  # refused while a writer holds its lock
    except BlockingIOError:
        return True
    except OSError:  # no flock on this file system
        return False
    finally:
        os.close(fd)  # and with it the shared lock just taken
    return False
